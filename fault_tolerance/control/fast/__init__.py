"""The Controller's compiled (numba) steps; each tested against the reference resolvers."""
