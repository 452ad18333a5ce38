"""websim: the command-line entry points around the simulation core."""
