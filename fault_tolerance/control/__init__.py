"""The real-time Controller: one preallocated workspace per arm, one call per control tick."""
