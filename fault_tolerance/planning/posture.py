"""Initial posture of the paper's Sec. III.D, step (i).

Step (i): at the start point ``x0`` with zero task velocity, move through the self-motion
(null space) to the configuration of minimum square-sum RCN ``K = Σ k_S²``. For one degree of
redundancy the self-motion manifold is a set of closed curves; :func:`self_motion_curve` traces
each one (predictor along the null vector, Newton corrector back onto ``x(q) = x0``) and
:func:`initial_posture` takes the global minimum over all of them. For ``r > 1`` it runs projected
gradient descent on ``K`` from several inverse-kinematics seeds (local, with restarts).

Steps (ii)-(iii), which run the path, are :func:`fault_tolerance.planning.paper_loop.plan` (a module above
:mod:`.simulation`; this one is below it, so the whole-path planner can start from here).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.planning.posture_steps import FastSteps, ReferenceSteps, norm
from fault_tolerance.planning.posture_steps import square_sum as _square_sum
from fault_tolerance.resolution.indices import rcn_gradient
from fault_tolerance.resolution.scenarios import Scenarios, scenarios

#: Largest task error [m or rad] of the start posture at x0 (else x0 counts as out of reach).
POSTURE_TOL = 1e-8


def _wrappable(arm: Arm) -> np.ndarray:
    """Joints whose limits span a full turn (revolute): their angles may wrap modulo 2π."""
    span = arm.upper - arm.lower
    return np.isfinite(span) & (span >= 2 * np.pi - 1e-3)


def wrap(arm: Arm, q: np.ndarray) -> np.ndarray:
    """Angles of full-turn joints wrapped into ``[-π, π)``; other joints unchanged."""
    q = np.array(q, dtype=float)
    w = _wrappable(arm)
    q[w] = (q[w] + np.pi) % (2 * np.pi) - np.pi
    return q


def joint_distance(arm: Arm, a: np.ndarray, b: np.ndarray):
    """Distance between configurations (rows), full-turn joints compared modulo 2π."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    w = _wrappable(arm)
    d[..., w] = (d[..., w] + np.pi) % (2 * np.pi) - np.pi
    return np.linalg.norm(d, axis=-1)


def _steps(arm: Arm, x_des: np.ndarray, reference: bool):
    """The search's steps at ``x_des``: the plain ones, or the same numbers without the checks."""
    return (ReferenceSteps if reference else FastSteps)(arm, x_des)


def inverse_kinematics(
    arm: Arm,
    x_des: np.ndarray,
    q_seed: np.ndarray,
    *,
    tol: float = 1e-10,
    max_iter: int = 200,
    reference: bool = False,
) -> np.ndarray | None:
    """Damped Newton on the task rows from ``q_seed``; ``None`` if it does not converge.

    ``reference=True`` runs the plain steps (:class:`.posture_steps.ReferenceSteps`); the default
    ones give the same numbers, bit for bit, faster.
    """
    x_des = np.asarray(x_des, dtype=float)
    if x_des.shape != (arm.m,):
        raise InvalidInput(f"x_des has shape {x_des.shape}; the task needs ({arm.m},)")
    return _newton(_steps(arm, x_des, reference), arm.check_q(q_seed).copy(), tol, max_iter)


def _newton(steps, q: np.ndarray, tol: float, max_iter: int) -> np.ndarray | None:
    for _ in range(max_iter):
        err = steps.error(q)
        if norm(err) < tol:
            return q
        step = steps.newton(steps.jacobian(q), err)
        size = norm(step)
        q = q + (step if size < 0.5 else step * 0.5 / size)
    return None


def _correct(steps, q: np.ndarray, iters: int = 8) -> np.ndarray:
    for _ in range(iters):
        err = steps.error(q)
        if norm(err) < 1e-12:
            break
        q = q + steps.newton(steps.jacobian(q), err)
    return q


def square_sum_rcn_at(arm: Arm, q: np.ndarray, sc: Scenarios) -> float:
    """``K(q) = Σ_S k_S²`` for the arm at ``q``."""
    return _square_sum(arm.jacobian(q), sc)


def self_motion_curve(
    arm: Arm,
    x0: np.ndarray,
    q_start: np.ndarray,
    *,
    step: float = 0.01,
    max_steps: int = 20000,
    reference: bool = False,
) -> tuple[np.ndarray, bool]:
    """Trace the self-motion curve through ``q_start`` at ``x(q) = x0`` (one degree of redundancy).

    Returns the points (shape (L, n), full-turn joints unwrapped) and whether the curve closed.
    An open curve (it runs into a joint limit of a joint that cannot wrap) is traced both ways.
    ``reference=True``: the plain steps (same numbers, slower).
    """
    if arm.redundancy != 1:
        raise InvalidInput(f"self-motion curves need r = 1; {arm.name} has r = {arm.redundancy}")
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != (arm.m,):
        raise InvalidInput(f"x0 has shape {x0.shape}; the task needs ({arm.m},)")
    pts, closed, _ = _curve(arm, _steps(arm, x0, reference), arm.check_q(q_start), step, max_steps)
    return pts, closed


def _curve(arm: Arm, steps, q_start: np.ndarray, step: float, max_steps: int = 20000):
    """``(points, closed, J at each point)`` of the self-motion curve through ``q_start``."""
    q_start = _correct(steps, q_start)
    hard, wrappable = ~_wrappable(arm), _wrappable(arm)
    lower, upper = arm.lower, arm.upper

    def walk(direction: float) -> tuple[list[np.ndarray], list[np.ndarray], bool]:
        pts, jacs = [q_start], []
        q = q_start
        prev = None
        for i in range(max_steps):
            J = steps.jacobian(q)
            jacs.append(J)
            N = steps.null_projector(J)
            nvec = N[:, int(np.argmax(np.diag(N)))]
            nvec = nvec / norm(nvec)
            if prev is None:
                nvec = nvec * direction * (1 if nvec[np.argmax(np.abs(nvec))] > 0 else -1)
            elif nvec @ prev < 0:
                nvec = -nvec
            prev = nvec
            q = _correct(steps, q + step * nvec)
            if np.any(hard & ((q < lower) | (q > upper))):
                return pts, jacs, False
            pts.append(q)
            if i > 10 and _distance(wrappable, q, q_start) < 1.5 * step:
                return pts, jacs + [steps.jacobian(q)], True
        return pts, jacs + [steps.jacobian(q)], False

    fwd, fwd_J, closed = walk(1.0)
    if closed:
        return np.array(fwd), True, fwd_J
    back, back_J, _ = walk(-1.0)
    return np.array(back[::-1] + fwd[1:]), False, back_J[::-1] + fwd_J[1:]


def _distance(wrappable: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """:func:`joint_distance` of two configurations (the mask of full-turn joints given)."""
    d = a - b
    d[wrappable] = (d[wrappable] + np.pi) % (2 * np.pi) - np.pi
    return math.sqrt(np.add.reduce(d * d))  # as np.linalg.norm(d, axis=-1) sums


@dataclass
class Posture:
    """Result of the initial-posture search."""

    q: np.ndarray  # best configuration, shape (n,)
    K: float  # its square-sum RCN
    candidates: list[tuple[float, np.ndarray]] = field(
        default_factory=list
    )  # local minima, best first
    curves: list[np.ndarray] = field(default_factory=list)  # traced self-motion curves (r = 1)
    method: str = ""
    curve_K: list[np.ndarray] = field(default_factory=list)  # K at every point of each curve


def _local_minima(values: np.ndarray, closed: bool) -> list[int]:
    n = len(values)
    idx = []
    for i in range(n):
        left = values[i - 1] if (i > 0 or closed) else np.inf
        right = values[(i + 1) % n] if (i < n - 1 or closed) else np.inf
        if values[i] <= left and values[i] <= right:
            idx.append(i)
    return idx


def initial_posture(
    arm: Arm,
    x0: np.ndarray,
    lockable=None,
    *,
    seeds: int | None = None,
    rng: np.random.Generator | None = None,
    step: float = 0.01,
    starts: Sequence[np.ndarray] | None = None,
    reference: bool = False,
) -> Posture:
    """Configuration of minimum square-sum RCN at ``x0`` (paper Sec. III.D, step i).

    ``r = 1``: global, over every self-motion curve found from ``seeds`` inverse-kinematics seeds
    (default 24). ``r > 1``: projected gradient descent on ``K`` from each seed (default 8; local
    minima, best kept). The reference configuration and the neutral one are always tried too.
    ``starts``: the inverse-kinematics seeds to use instead of those (e.g. one configuration that
    reaches ``x0``: then only its own self-motion is searched). ``reference=True``: the plain steps
    (:class:`.posture_steps.ReferenceSteps`); the default ones give the same numbers, faster.

    Raises:
        InvalidInput: ``x0`` has the wrong size or no seed reaches it (out of reach).
    """
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != (arm.m,) or not np.all(np.isfinite(x0)):
        raise InvalidInput(
            f"x0 must be {arm.m} finite numbers for task {'/'.join(arm.task)}, got {x0.tolist()}"
        )
    rng = rng or np.random.default_rng(0)
    if seeds is None:  # a global search needs many seeds; descent from each is costlier
        seeds = 24 if arm.redundancy == 1 else 8
    sc = scenarios(
        arm.default_lockable if lockable is None else lockable,
        arm.n,
        r=arm.redundancy,
        joint_names=arm.joint_names,
    )
    if starts is None:
        starts = [arm.q_reference, arm.neutral()] + [arm.random_q(rng) for _ in range(seeds)]
    steps = _steps(arm, x0, reference)
    sols = _solutions(arm, steps, starts)
    if not sols:
        raise InvalidInput(
            f"x0 = {x0.tolist()} is out of reach of {arm.name}, or on the edge of its workspace (no "
            f"inverse-kinematics solution from {len(starts)} seeds within the joint limits)"
        )
    if arm.redundancy == 1:
        posture = _posture_on_curves(arm, steps, sols, sc, step)
    else:
        posture = _posture_by_descent(arm, steps, sols, sc)
    miss = float(np.linalg.norm(arm.task_error(x0, posture.q)))
    if miss > POSTURE_TOL:  # only singular configurations reach x0: the search drifted off it
        raise InvalidInput(
            f"x0 = {x0.tolist()} is at the edge of {arm.name}'s workspace: only singular "
            f"configurations reach it and the posture search ends {miss:.2g} away; move x0 inward"
        )
    return posture


def _solutions(arm: Arm, steps, starts: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Inverse-kinematics solutions from ``starts`` inside the joint limits (full turns wrap)."""
    sols = [_newton(steps, arm.check_q(q).copy(), 1e-10, 200) for q in starts]
    wraps = _wrappable(arm)
    return [
        s for s in sols if s is not None and np.all(wraps | ((s >= arm.lower) & (s <= arm.upper)))
    ]


def reaches(arm: Arm, x: np.ndarray, near: Sequence[np.ndarray] = (), seeds: int = 8) -> bool:
    """Whether a configuration inside the joint limits puts the tool at ``x`` (task coordinates).

    The inverse kinematics of :func:`initial_posture` from the configurations ``near``, the
    reference and neutral ones and ``seeds`` random ones (seeded): ``False`` when none converges,
    i.e. ``x`` is out of reach, or on the edge of the workspace (only singular configurations
    reach it).
    """
    rng = np.random.default_rng(0)
    starts = [*near, arm.q_reference, arm.neutral()] + [arm.random_q(rng) for _ in range(seeds)]
    return bool(_solutions(arm, _steps(arm, np.asarray(x, dtype=float), False), starts))


def _posture_on_curves(arm, steps, sols, sc, step) -> Posture:
    curves: list[np.ndarray] = []
    curve_K: list[np.ndarray] = []
    cands: list[tuple[float, np.ndarray]] = []
    for s in sols:
        if any(np.min(joint_distance(arm, c, s)) < 5 * step for c in curves):
            continue
        pts, closed, jacs = _curve(arm, steps, s, step)
        curves.append(pts)
        K = steps.square_sums(jacs, sc)
        curve_K.append(K)
        for i in _local_minima(K, closed):
            cands.append((float(K[i]), wrap(arm, pts[i])))
    cands.sort(key=lambda c: c[0])
    best = _refine_on_curve(arm, steps, cands[0][1], sc, step)
    cands[0] = (square_sum_rcn_at(arm, best, sc), best)
    return Posture(
        best, cands[0][0], cands, curves, "global search over self-motion curves", curve_K
    )


def _refine_on_curve(arm, steps, q, sc, step) -> np.ndarray:
    """Golden-section search along the curve within ±step of a sampled minimum."""
    N = steps.null_projector(steps.jacobian(q))
    nvec = N[:, int(np.argmax(np.diag(N)))]
    nvec /= norm(nvec)

    def at(s):
        return _correct(steps, q + s * nvec)

    def K(q):
        return _square_sum(steps.jacobian(q), sc)

    a, b = -step, step
    g = (np.sqrt(5) - 1) / 2
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = K(at(c)), K(at(d))
    for _ in range(30):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = K(at(c))
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = K(at(d))
    best = wrap(arm, at((a + b) / 2))
    return best if K(best) <= K(q) else q


def _posture_by_descent(arm, steps, sols, sc, iters: int = 300) -> Posture:
    cands = []
    for q in sols:
        K = square_sum_rcn_at(arm, q, sc)
        alpha = 1e-3
        for _ in range(iters):
            J = steps.jacobian(q)
            dK = rcn_gradient(J, arm.jacobian_derivatives(q), sc, singular="escape")  # (S1)
            g = steps.null_projector(J) @ dK
            if norm(g) < 1e-9:
                break
            trial = _correct(steps, q - alpha * g / max(1.0, norm(g)))
            Kt = _square_sum(steps.jacobian(trial), sc)
            if Kt < K:
                q, K, alpha = trial, Kt, alpha * 1.5
            else:
                alpha *= 0.5
                if alpha < 1e-8:
                    break
        cands.append((K, wrap(arm, q)))
    cands.sort(key=lambda c: c[0])
    return Posture(cands[0][1], cands[0][0], cands, [], "projected gradient descent with restarts")


def lockable_scenarios(arm: Arm, lockable: Sequence | None) -> Scenarios:
    """The arm's scenarios for ``lockable`` (default: its default lockable joints)."""
    return scenarios(
        arm.default_lockable if lockable is None else lockable,
        arm.n,
        r=arm.redundancy,
        joint_names=arm.joint_names,
    )
