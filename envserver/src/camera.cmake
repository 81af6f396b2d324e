# Sources of the envserver camera area (added to indrive_envserver).
