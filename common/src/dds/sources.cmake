# Sources of common/dds (added to indrive_common).
