"""Numba kernels shared by the backends: one implementation of each piece of arithmetic."""

import tofnet.numba_cache  # noqa: F401  (before any kernel is defined: its cache is keyed on every source)
from tofnet.kernels import compilation  # noqa: F401  (watch numba from the first kernel on: compile time is not run time)
