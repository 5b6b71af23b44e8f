"""Compiled (numba) dense linear algebra shared by the compiled kernels of the layers above."""
