# Tests of the envserver sim area.
