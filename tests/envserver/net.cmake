# Tests of the envserver net area.
