"""The run's files and process handling: output folders, atomic writes, the shipped data
folders, signals, numba's cache, the command lines' shared options and the TOML checker
every input file goes through. Nothing here knows the control problem."""
