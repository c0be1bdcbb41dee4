"""The physics stages of a step, as Taichi functions and kernels: forces, wind, constraints (relaxation, XPBD), strain limiting, tearing, handles and their paths."""
