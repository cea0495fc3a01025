"""Numba kernels over contiguous particle and node arrays."""
