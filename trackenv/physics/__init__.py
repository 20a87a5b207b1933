"""Physics of the standing ballasted track: numpy/scipy/numba only (no RL, no plotting, no printing)."""
