"""Numba kernels shared by the backends: one implementation of each piece of arithmetic."""
