"""How the model code runs: compiled by numba, or as the same functions in plain Python."""
