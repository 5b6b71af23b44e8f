"""Failure-tolerant workspaces: closed form for planar arms, sampled for any arm, and the result."""
