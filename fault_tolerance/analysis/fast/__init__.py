"""Compiled (numba) row loops of the batched API."""
