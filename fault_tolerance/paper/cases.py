"""The paper's cases as data (docs/MATH.md's table): the Sec. IV comparisons and the Sec. V lock.

The first stop of ``reproduce``: :data:`CASES` (Figs. 2-4, 6-7) and :data:`EXPERIMENT` (the
Power-Cube lock of Figs. 9-10) say which arm, which lockable joints, which start point and which
circle; :mod:`.paper_runs` runs them, :mod:`.experiments` writes the results.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.setup import ServoModel

ALGORITHMS = ("lnva", "jvja", "mda")


@dataclass(frozen=True)
class Case:
    """One comparison case of the paper's Sec. IV."""

    key: str
    robot: str
    lockable: tuple[str, ...]
    x0: tuple[float, ...]
    radius: float  # [m]
    omega: float  # [rad/s]
    rows: tuple[int, int]
    duration: float = 1.0
    sign: float = 1.0
    title: str = ""

    def path(self, duration: float | None = None) -> CirclePath:
        """The task path of the case."""
        return CirclePath(
            np.array(self.x0),
            self.radius,
            self.omega,
            duration or self.duration,
            rows=self.rows,
            sign=self.sign,
            name=self.key,
        )


ALL3 = ("joint1", "joint2", "joint3")
CASES: dict[str, Case] = {
    c.key: c
    for c in [
        Case(
            "fig2",
            "planar_3r",
            ALL3,
            (0.35, 0.0),
            0.1,
            2 * np.pi,
            (0, 1),
            title="Fig. 2 — planar 3R, all joints lockable, start (0.35, 0) m",
        ),
        Case(
            "fig3",
            "planar_3r",
            ALL3,
            (0.40, 0.0),
            0.1,
            2 * np.pi,
            (0, 1),
            title="Fig. 3 — planar 3R, all joints lockable, start (0.40, 0) m",
        ),
        Case(
            "fig4",
            "planar_3r",
            ("joint2", "joint3"),
            (0.35, 0.0),
            0.1,
            2 * np.pi,
            (0, 1),
            title="Fig. 4 — planar 3R, joints 2 and 3 lockable, start (0.35, 0) m",
        ),
        Case(
            "fig6",
            "spatial_4r",
            ALL3,
            (0.09, 0.21, 0.27),
            0.075,
            2 * np.pi,
            (1, 2),
            title="Fig. 6 — spatial 4R, joints 1-3 lockable, start (0.09, 0.21, 0.27) m",
        ),
        Case(
            "fig7",
            "spatial_4r",
            ALL3,
            (-0.21, 0.20, 0.35),
            0.075,
            2 * np.pi,
            (1, 2),
            title="Fig. 7 — spatial 4R, joints 1-3 lockable, start (-0.21, 0.20, 0.35) m",
        ),
    ]
}


@dataclass(frozen=True)
class LockExperiment:
    """The Power-Cube experiment of Sec. V: LNVA, joint 3 locks at the largest / smallest jump."""

    robot: str = "powercube_3r"
    joint: str = "joint3"
    #: The paper does not give the start; we pick a point well inside the workspace.
    x0: tuple[float, float] = (0.50, 0.0)
    radius: float = 0.1  # ẋ = [-(π/30) sin(πt/3), (π/30) cos(πt/3)]: radius 0.1 m, ω = π/3
    omega: float = np.pi / 3
    duration: float = 6.0
    after_lock: float = 1.5  # the lock runs go on at least this long after the lock [s]
    servo: ServoModel = field(default_factory=lambda: ServoModel(tau=0.05))
    feedback_gain: float = 10.0  # [1/s], in the planned run and after the lock alike
    paper_t_max: float = 3.1
    paper_t_min: float = 4.5

    def path(self, duration: float) -> CirclePath:
        """The Power-Cube task path (a circle travelled once in 6 s)."""
        return CirclePath(
            np.array(self.x0),
            self.radius,
            self.omega,
            duration,
            rows=(0, 1),
            sign=-1.0,
            name="powercube",
        )


EXPERIMENT = LockExperiment()
