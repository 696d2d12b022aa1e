"""Numba kernels shared by the backends: one implementation of each piece of arithmetic."""

from tofnet.kernels import compilation  # noqa: F401  (watch numba from the first kernel on: compile time is not run time)
