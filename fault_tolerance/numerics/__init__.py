"""Numerical building blocks: pseudo-inverses, projectors and small dense factorisations."""
