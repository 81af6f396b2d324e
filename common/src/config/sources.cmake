# Sources of common/config (added to indrive_common).
