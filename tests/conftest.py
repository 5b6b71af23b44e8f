"""Shared fixtures: the shipped arms, the Panda, seeded RNGs and well-conditioned configurations.

Every robot fixture is a :class:`RobotCase`: the arm and the lockable set the tests use for it.

* ``planar_3r``, ``powercube_3r``: every joint lockable (paper §IV.A, §V), r = 1.
* ``spatial_4r``: joints 0, 1, 2 lockable; joint index 3 (``joint4``) is intolerable (paper §IV.B).
* ``panda_pose``: 6-row task, r = 1. The elbow (``panda_joint4``, index 3) sets the shoulder-wrist
  distance almost alone, so its pivot ``N[3, 3]`` is typically ~3e-3 and near-intolerable; the
  lockable set is the other six joints.
* ``panda_position``: 3-row task, r = 4, every joint lockable.
"""

from __future__ import annotations

import os
import signal
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

# The CLI tests compare stderr line by line: numba compiles on use there, silently, whatever
# the state of the cache (tests/test_warm.py tests the default, compiling ahead).
os.environ.setdefault("FAULT_TOLERANCE_FIRST_RUN", "on-use")
#: The suite's compiled cache, in the checkout: a clean clone starts cold, and every worker and
#: every subprocess (the CLI tests, the wheel of tests/test_docs.py) shares what one compiled.
os.environ.setdefault(
    "FAULT_TOLERANCE_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".cache" / "kernels")
)

import fault_tolerance as ft  # noqa: E402
from fault_tolerance.numerics.linalg import min_pivot  # noqa: E402

#: The kernel groups compiled before the first test, split over two processes (both cores).
WARM_SPLIT = (("bounded",), ("controller", "multi", "simulate", "floor"))


def pytest_terminal_summary(terminalreporter) -> None:
    """Under ``.ci/run``: how long the whole script has taken, install included (before pytest's
    closing line)."""
    import time

    start = os.environ.get("FT_CI_START", "")
    if start.isdigit():
        spent = time.time() - int(start)
        terminalreporter.write_line(f".ci/run: install and tests took {spent / 60:.1f} min")


def pytest_configure(config) -> None:
    """Compile every kernel once, before any test, in the controlling process (not in a worker).

    Two ``python -m fault_tolerance.bench.warm`` processes share the cache; a warm cache costs
    about a second. Tests about a cold start use caches of their own.
    """
    import subprocess
    import sys
    import time

    if hasattr(config, "workerinput") or config.option.collectonly:
        return
    from fault_tolerance.bench.warm import cold_groups

    if not cold_groups():
        return
    t0 = time.monotonic()
    procs = [subprocess.Popen([sys.executable, "-m", "fault_tolerance.bench.warm", *groups],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
             for groups in WARM_SPLIT]  # fmt: skip
    errors = [p.communicate()[1] for p in procs if p.wait() != 0]
    if errors:
        raise pytest.UsageError(f"compiling the fast path failed:\n{errors[0][-3000:]}")
    cache = os.environ["FAULT_TOLERANCE_CACHE_DIR"]
    print(f"tests: compiled the fast path into {cache} in {time.monotonic() - t0:.0f} s")


#: Base seed of every RNG in the suite.
SEED = 20240521
#: Repository root (for ``robots/*.urdf``).
ROOT = Path(__file__).resolve().parents[1]

SHIPPED = ("planar_3r", "spatial_4r", "powercube_3r")
ALL_ROBOTS = SHIPPED + ("panda_pose", "panda_position")
R1_ROBOTS = SHIPPED + ("panda_pose",)


@dataclass(frozen=True)
class RobotCase:
    """One arm and the lockable set (column indices, or tuples for multi-joint scenarios)."""

    id: str
    arm: ft.Arm
    lockable: tuple
    multi_sets: tuple | None = None  # overrides the default multi-joint scenarios

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.arm.n

    @property
    def m(self) -> int:
        """Number of task rows."""
        return self.arm.m

    @property
    def r(self) -> int:
        """Degree of redundancy."""
        return self.arm.redundancy

    @property
    def multi(self) -> list[tuple[int, ...]]:
        """Multi-joint scenarios the arm allows (|S| <= r): none for r = 1."""
        if self.multi_sets is not None:
            return list(self.multi_sets)
        out: list[tuple[int, ...]] = []
        if self.r >= 2:
            out += [(0, 1), (2, 3), (1, 5), (4, 6)]
        if self.r >= 3:
            out += [(0, 2, 4), (1, 3, 6)]
        if self.r >= 4:
            out += [(0, 2, 4, 6)]
        return [S for S in out if max(S) < self.n]

    @property
    def sets(self) -> list[tuple[int, ...]]:
        """Singletons of the lockable set, then the multi-joint scenarios the arm allows."""
        return [(i,) for i in self.lockable] + self.multi

    def __repr__(self) -> str:
        return f"RobotCase({self.id})"


def well_conditioned(
    arm: ft.Arm,
    q: np.ndarray,
    lockable: Sequence,
    *,
    max_cond: float = 100.0,
    min_sigma: float = 1e-2,
    min_pivot_value: float = 1e-2,
) -> bool:
    """True when J(q) is far from singular (no damping) and no scenario is near-intolerable."""
    J = arm.jacobian(q)
    s = np.linalg.svd(J, compute_uv=False)
    if s[-1] < min_sigma or s[0] / s[-1] > max_cond:
        return False
    N = ft.nullspace_projector(J)
    sc = ft.scenarios(list(lockable), arm.n, r=arm.redundancy)
    return min(min_pivot(N, S) for S in sc.sets) >= min_pivot_value


def random_well_conditioned_q(
    arm: ft.Arm, rng: np.random.Generator, lockable: Sequence, *, tries: int = 2000, **criteria
) -> np.ndarray:
    """A configuration uniform within the limits, redrawn until :func:`well_conditioned`."""
    for _ in range(tries):
        q = arm.random_q(rng)
        if well_conditioned(arm, q, lockable, **criteria):
            return q
    raise RuntimeError(f"no well-conditioned configuration of {arm.name} in {tries} draws")


def random_xdot(rng: np.random.Generator, m: int) -> np.ndarray:
    """A task velocity of unit norm, shape (m,)."""
    v = rng.standard_normal(m)
    return v / np.linalg.norm(v)


def _case(id_: str, robot: str, lockable: tuple, multi_sets=None, **kw) -> RobotCase:
    return RobotCase(id_, ft.load_arm(robot, **kw), lockable, multi_sets)


@pytest.fixture(scope="session")
def planar_3r() -> RobotCase:
    """Planar 3R, links 0.5 m, task (x, y), every joint lockable."""
    return _case("planar_3r", "planar_3r", (0, 1, 2))


@pytest.fixture(scope="session")
def spatial_4r() -> RobotCase:
    """Spatial 4R, position task, joints 0, 1, 2 lockable (joint index 3 is intolerable)."""
    return _case("spatial_4r", "spatial_4r", (0, 1, 2))


@pytest.fixture(scope="session")
def powercube_3r() -> RobotCase:
    """Power-Cube planar 3R, task (x, y), every joint lockable."""
    return _case("powercube_3r", "powercube_3r", (0, 1, 2))


@pytest.fixture(scope="session")
def panda_pose() -> RobotCase:
    """example-robot-data Panda, full pose (r = 1), every joint but the elbow lockable."""
    return _case("panda_pose", "panda", (0, 1, 2, 4, 5, 6), task="pose")


@pytest.fixture(scope="session")
def panda_position() -> RobotCase:
    """example-robot-data Panda, position task (r = 4), every joint lockable."""
    return _case("panda_position", "panda", tuple(range(7)), task="position")


@pytest.fixture(scope="session")
def ur5_position() -> RobotCase:
    """example-robot-data UR5, position task (r = 3), every joint lockable.

    wrist_3 (index 5) does not move tool0's origin, so a scenario is tolerable only if the joints
    left unlocked among 0-4 still span the position: the multi-joint scenarios are chosen so.
    """
    return _case(
        "ur5_position",
        "ur5",
        tuple(range(6)),
        task="position",
        multi_sets=((0, 1), (2, 3), (1, 4), (0, 3, 5)),
    )


@pytest.fixture(scope="session", params=ALL_ROBOTS)
def robot(request) -> RobotCase:
    """Each of the three shipped arms and the Panda's pose and position tasks."""
    return request.getfixturevalue(request.param)


@pytest.fixture(scope="session", params=R1_ROBOTS)
def r1_robot(request) -> RobotCase:
    """Each arm with one degree of redundancy (the shipped arms and the Panda's pose task)."""
    return request.getfixturevalue(request.param)


@pytest.fixture(scope="session", params=["panda_position", "ur5_position"])
def redundant_robot(request) -> RobotCase:
    """Arms with r > 1: the Panda position task (r = 4) and the UR5 position task (r = 3)."""
    return request.getfixturevalue(request.param)


@pytest.fixture(scope="session", params=SHIPPED)
def shipped_robot(request) -> RobotCase:
    """Each of the three shipped arms."""
    return request.getfixturevalue(request.param)


@pytest.fixture
def rng(request) -> np.random.Generator:
    """A generator seeded from SEED and the test's id: reproducible, different per test."""
    return np.random.default_rng([SEED, zlib.crc32(request.node.nodeid.encode())])


@pytest.fixture(scope="session")
def draw_q() -> Callable[..., np.ndarray]:
    """``draw_q(case, rng, lockable=None, **criteria)``: a random well-conditioned configuration."""

    def draw(case: RobotCase, rng: np.random.Generator, lockable=None, **criteria) -> np.ndarray:
        lock = case.lockable if lockable is None else lockable
        return random_well_conditioned_q(case.arm, rng, lock, **criteria)

    return draw


@pytest.fixture(scope="session")
def draw_xdot() -> Callable[[np.random.Generator, int], np.ndarray]:
    """``draw_xdot(rng, m)``: a random task velocity of unit norm."""
    return random_xdot


def default_sigint() -> None:
    """``preexec_fn`` of a child the test interrupts: SIGINT at its default disposition.

    A runner started in the background by a shell without job control inherits SIGINT ignored,
    and so would the child (Python then never raises KeyboardInterrupt); Ctrl-C tests would
    test the runner's shell instead of the command.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)
