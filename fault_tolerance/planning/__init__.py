"""Planning before and along a run: the default start, the initial posture, the paper's loop, whole paths."""
