"""The fast path compiled once, ahead of its use, with one line of progress on stderr.

numba compiles a kernel at its first call and caches it on disk (``cache=True``). From an empty
cache that is a minute or more of CPU, which a command would otherwise spend silently inside its
first run. This module compiles the kernels by group, each group by running the code that uses
them on a small problem, and marks a group done beside numba's cache
(:func:`fault_tolerance.fast_cache.mark_warm`), so a later command knows it has nothing to compile.

Groups (:data:`GROUPS`): ``controller`` (the Controller's LNVA / single-joint JVJA steps),
``multi`` (its multi-joint JVJA step), ``bounded`` (its bounded step under joint limits), ``simulate`` (the compiled sample
of :func:`~fault_tolerance.simulation.simulate.simulate`, with and without limits, bounds met),
``floor`` (the benchmark's floor).

``fault-tolerance warm [GROUP ...]`` (or ``python -m fault_tolerance.bench.warm``) compiles the
groups (default: all) in the foreground. No command compiles in the background: a short first
``simulate`` takes the reference engine and says how to warm the cache.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Sequence

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.fast_cache import is_warm, mark_warm

__all__ = [
    "GROUPS",
    "Notice",
    "cold_groups",
    "compile_ahead",
    "warm",
]

#: Seconds a compilation may take before it says so on stderr.
QUIET_SECONDS = 2.0
#: The env variable that chooses what a command does with a cold fast path: ``"ahead"``
#: (default: compile ahead, with one line on stderr, or take the reference engine for a short
#: run) or ``"on-use"`` (numba compiles each kernel at its first call, inside the command,
#: silently: the behaviour before; the test suite, whose CLI tests compare stderr exactly).
FIRST_RUN = "FAULT_TOLERANCE_FIRST_RUN"
FIRST_RUN_POLICIES = ("ahead", "on-use")


def _planar():
    from fault_tolerance.model.loading import load_arm

    return load_arm("planar_3r"), np.array([0.3, 1.2, 1.0])


def _compiled_resolvers(modes: Sequence[int] | None = None) -> list[str]:
    """One registered resolver per compiled kernel mode (of ``modes``; the built-ins), in order.

    The kernels to compile are those of the registry's entries (``ResolverEntry.compiled``); a
    resolver without a compiled kernel has nothing to warm.
    """
    from fault_tolerance.resolution.registry import get, names

    chosen: dict[int, str] = {}
    for name in names():
        mode = get(name).compiled
        if mode is not None and (modes is None or mode in modes):
            chosen.setdefault(mode, name)
    return list(chosen.values())


def _controller() -> None:
    """The Controller's compiled steps: LNVA and single-joint JVJA."""
    from fault_tolerance.control.controller import Controller

    arm, q = _planar()
    Controller(arm, lockable="all", backend="numba", limits=False).step(q, np.array([0.1, 0.0]))


def _multi() -> None:
    """The Controller's compiled multi-joint JVJA step (G1)."""
    from fault_tolerance.control.controller import Controller
    from fault_tolerance.model.loading import load_arm

    panda = load_arm("panda", task="position")
    pairs = [(j, j + 1) for j in range(panda.n - 1)]
    Controller(panda, pairs, backend="numba", limits=False)


def _bounded() -> None:
    """The Controller's bounded step (box check, bounded solve): LNVA and JVJA (MDA: reference)."""
    from fault_tolerance.control.controller import Controller

    arm, q = _planar()
    for method in _compiled_resolvers():
        ctrl = Controller(arm, lockable="all", method=method, backend="numba")
        ctrl.step(q, np.array([5.0, 0.0]))  # out of the box: the bounded solve


def _simulate() -> None:
    """The compiled sample, with and without limits, along a circle fast enough to meet bounds."""
    from fault_tolerance.simulation.paths import CirclePath
    from fault_tolerance.simulation.simulate import simulate

    arm, q = _planar()
    for radius, omega in ((0.01, 2 * np.pi), (0.1, 40.0)):  # the second meets the rate box
        path = CirclePath(arm.fk(q), radius, omega, 0.05, rows=(0, 1))
        for alg in _compiled_resolvers():
            for limits in (False, True):
                simulate(
                    arm, path, alg, q0=q, lockable="all", dt=1e-2, limits=limits, engine="fast"
                )
    path = CirclePath(arm.fk(q), 0.01, 2 * np.pi, 0.05, rows=(0, 1))
    simulate(arm, path, "jvja", q0=q, lockable="all", dt=1e-2, lock_joint=1, lock_time=0.02)


def _floor() -> None:
    """The benchmark's floor kernel."""
    from fault_tolerance.control.fast.step import compiled_kernel

    compiled_kernel("floor")(np.eye(2, 3), np.zeros(2), np.zeros(3), np.zeros((2, 2)), np.zeros(2))


#: Group name -> what compiles it, in the order they build on each other.
GROUPS: dict[str, Callable[[], None]] = {
    "controller": _controller,
    "multi": _multi,
    "bounded": _bounded,
    "simulate": _simulate,
    "floor": _floor,
}


def _numba() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:  # pragma: no cover - numba is a core dependency
        return False
    return True


#: Group -> ``(module, kernel)``: the top-level kernels whose cached code shows the group is
#: compiled even without a marker (compiled by ordinary use rather than by :func:`warm`).
KERNELS: dict[str, tuple[tuple[str, str], ...]] = {
    "controller": (("fault_tolerance.control.fast.step", "packed_step_kernel"),),
    "multi": (("fault_tolerance.control.fast.multi_step", "multi_kernel"),),
    "bounded": (("fault_tolerance.control.fast.bounded_solve", "free_then_bounded"),),
    "simulate": (
        ("fault_tolerance.simulation.fast.sample", "sample_kernel"),
        ("fault_tolerance.simulation.fast.sample", "finish_kernel"),
        ("fault_tolerance.control.fast.bounded_solve", "reduced_solve"),
    ),
}


def _cached(module: str, name: str) -> bool:
    """Whether numba's on-disk cache holds compiled code of ``module.name`` for its source."""
    import importlib

    try:
        kernel = getattr(importlib.import_module(module), name)
        # numba's index of the kernel's cached overloads; empty when absent or stale
        return bool(kernel._cache._cache_file._load_index())
    except Exception:  # noqa: BLE001 - numba's internals moved: take it as not cached
        return False


def _compiled(group: str) -> bool:
    """The group's marker holds, or every one of its top-level kernels is in the cache."""
    if is_warm(group):
        return True
    kernels = KERNELS.get(group, ())
    return bool(kernels) and all(_cached(*k) for k in kernels)


def compile_ahead() -> bool:
    """Whether commands compile ahead (:data:`FIRST_RUN` is ``"ahead"``, the default)."""
    policy = os.environ.get(FIRST_RUN, "ahead")
    if policy not in FIRST_RUN_POLICIES:
        raise InvalidInput(f"{FIRST_RUN}={policy!r} is not one of {list(FIRST_RUN_POLICIES)}")
    return policy == "ahead"


def cold_groups(groups: Sequence[str] = tuple(GROUPS)) -> list[str]:
    """The groups of ``groups`` not yet compiled into the cache (none without numba)."""
    bad = [g for g in groups if g not in GROUPS]
    if bad:
        raise InvalidInput(f"kernel groups {bad} are not among {list(GROUPS)}")
    return [g for g in groups if not _compiled(g)] if _numba() else []


class Notice:
    r"""One line on stderr, once the work has taken :data:`QUIET_SECONDS`: its progress, then done.

    On a terminal the line is rewritten in place (``\r``); elsewhere (a log, a pipe) the progress
    is appended to it. Either way the notice is one line, ended when :meth:`close` is called.
    """

    def __init__(self, what: str, total: int, stream=None, quiet: float = QUIET_SECONDS) -> None:
        self.what, self.total = what, total
        self.stream = sys.stderr if stream is None else stream
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.done, self.shown, self.t0 = 0, False, time.monotonic()
        self.lock = threading.Lock()
        self.timer = threading.Timer(quiet, self._show)
        self.timer.daemon = True
        self.timer.start()

    def _text(self) -> str:
        return f"fault-tolerance: {self.what} once (kernel group {self.done + 1}/{self.total})…"

    def _show(self) -> None:
        with self.lock:
            if self.done < self.total and not self.shown:
                self.shown = True
                self.stream.write(self._text())
                self.stream.flush()

    def step(self) -> None:
        """One more group done."""
        with self.lock:
            self.done += 1
            if self.shown and self.done < self.total:
                if self.tty:
                    self.stream.write("\r\033[K" + self._text())
                else:
                    self.stream.write(f" {self.done + 1}/{self.total}…")
                self.stream.flush()

    def close(self) -> None:
        """End the line (when it was shown) with the time taken."""
        self.timer.cancel()
        with self.lock:
            if self.shown:
                self.stream.write(f" done in {time.monotonic() - self.t0:.0f} s\n")
                self.stream.flush()
                self.shown = False


def warm(
    groups: Sequence[str] = tuple(GROUPS),
    stream=None,
    what: str | None = None,
    force: bool = False,
) -> list[str]:
    """Compile the cold groups of ``groups`` into numba's cache; the groups run.

    ``force``: run every group of ``groups`` (its kernels then loaded in this process, as the
    benchmark needs before it times them), not only the cold ones. Says so on one line of
    ``stream`` (stderr) when it takes longer than :data:`QUIET_SECONDS`.
    """
    todo = cold_groups(groups)
    if force and _numba():
        todo = list(groups)
    if not todo:
        return []
    notice = Notice(what or "compiling the fast path", len(todo), stream)
    try:
        for group in todo:
            GROUPS[group]()
            mark_warm(group)
            notice.step()
    finally:
        notice.close()
    return todo


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m fault_tolerance.bench.warm [GROUP ...]``: compile (default: every group), exit 0."""
    args = list(sys.argv[1:] if argv is None else argv)
    warm(args or tuple(GROUPS))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
