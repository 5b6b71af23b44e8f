"""Largest difference between the Controller's compiled JVJA step and ``ft.resolve`` (eigh).

Random configurations inside the limits of an arm; prints the largest difference relative to the
rates' norm, and there the smallest singular value of J and the smallest pivot N_ii::

    python scripts/controller_vs_resolve.py panda pose 2000
"""

from __future__ import annotations

import sys

import numpy as np

import fault_tolerance as ft
from fault_tolerance.control.controller import Controller


def main(robot: str = "panda", task: str = "pose", samples: int = 2000) -> None:
    """Print the worst relative difference of the two steps over ``samples`` configurations."""
    arm = ft.load_arm(robot, task=task)
    ctrl = Controller(arm, "all", backend="numba", limits=False)
    rng = np.random.default_rng(0)
    worst, at = 0.0, None
    for _ in range(samples):
        q, xd = arm.random_q(rng), rng.standard_normal(arm.m)
        try:
            ref = ft.resolve("jvja", arm.jacobian(q), xd, lockable="all")
        except ft.FaultToleranceError:
            continue
        d = float(np.linalg.norm(ctrl.jvja(q, xd) - ref) / np.linalg.norm(ref))
        if d > worst:
            J = arm.jacobian(q)
            pivot = float(np.diag(ft.nullspace_projector(J)).min())
            worst, at = d, (np.linalg.svd(J, compute_uv=False)[-1], pivot)
    print(
        f"{robot} {task}: largest relative difference {worst:.2e} "
        f"(there σ_min(J) {at[0]:.3g}, smallest pivot N_ii {at[1]:.3g})"
    )


if __name__ == "__main__":
    args = sys.argv[1:]
    main(*(args[:2]), *(int(a) for a in args[2:3]))
