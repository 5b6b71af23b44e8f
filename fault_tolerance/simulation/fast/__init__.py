"""The compiled simulated sample; tested against :mod:`fault_tolerance.simulation.reference_step`."""
