"""The compiled path (extra `fast`: numba): a scene's generated code and the loops around it,
compiled. May import every physics group but simulator and batch."""
