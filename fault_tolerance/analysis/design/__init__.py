"""Design of arms for fault tolerance: the design problem and its search."""
