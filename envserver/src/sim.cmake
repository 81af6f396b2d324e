# Sources of the envserver sim area (added to indrive_envserver).
