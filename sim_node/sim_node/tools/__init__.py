"""Tools of the simulated world (benchmark)."""
