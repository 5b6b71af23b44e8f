"""Redundancy resolution: failure scenarios, the paper's indices, the resolvers and the bounded QP."""
