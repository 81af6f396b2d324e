# Tests of the envserver camera area.
