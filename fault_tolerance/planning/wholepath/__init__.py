"""Whole-path minimum-jump planning.

The local planners choose the rates at each instant; this package plans the whole path: it
minimises the mean (or the maximum) of the square-sum jump λ(t) subject to ``J q̇ = ẋ_cmd`` at every
step (the same task feedback as the other planners), the joint position and velocity limits and
optionally a bound on the reduced condition numbers. One degree of redundancy: dynamic programming
over the self-motion parameter (:mod:`.dp`), refined by sequential convex programming; more:
sequential convex programming (:mod:`.scp`) warm-started from the better of LNVA and JVJA.
"""
