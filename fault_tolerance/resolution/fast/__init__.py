"""Compiled (numba) copies of the bounded QP and its bases; tested against resolution's references."""
