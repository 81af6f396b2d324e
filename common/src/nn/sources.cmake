# Sources of common/nn (added to indrive_common).
