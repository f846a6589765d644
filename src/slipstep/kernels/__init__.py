"""Compiled (numba) kernels. They import nothing from the package but other kernels,
hold no Python objects, write into preallocated arrays and return status codes."""
