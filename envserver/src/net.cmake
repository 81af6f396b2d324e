# Sources of the envserver net area (added to indrive_envserver).
