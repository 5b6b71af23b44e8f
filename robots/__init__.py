"""URDF descriptions shipped with fault_tolerance (data only)."""
