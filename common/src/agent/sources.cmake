# Sources of common/agent (added to indrive_common).
