"""Design of a planar 3R for fault tolerance: artificial limits and link lengths (MATH.md (F5)).

A *design* is artificial limits ``A = Π [c_i − w_i, c_i + w_i]`` inside the physical limits and,
with ``vary="links,limits"``, link lengths with their sum fixed (each at least
:data:`MIN_LINK_SHARE` of it). Objectives:

* ``ftw-area``: the failure-tolerant workspace's area (maximised). It does not depend on joint 1's
  centre (turning joint 1 turns the whole workspace), so ``c_1`` stays at the physical centre.
* ``jvj`` / ``rcn``: the mean square-sum jump λ (9) / mean K (15) of JVJA along the circle task,
  from the start of minimum K on the self-motion within ``A`` (the planning step (i) restricted to
  ``A``), minimised; a design whose run leaves ``A`` or whose max K exceeds ``rcn_max`` is
  infeasible. Both indices are kept for every candidate, and the Pareto front between them is
  reported.

The search is seeded and deterministic: ``candidates`` quasi-random designs, then ``rounds`` of a
pattern search around the best (coordinate steps, halved each round). Every round is a sweep
(:func:`.sweep.run`): chunked, on Dask when asked, resumable from its finished chunks.

Example:
    >>> import fault_tolerance as ft
    >>> from fault_tolerance.analysis.design.search import design
    >>> d = design(ft.load_arm("planar_3r"), objective="ftw-area", candidates=8, rounds=0, grid=31)
    >>> d.record["area_ftw"] > 0
    True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from fault_tolerance.analysis import batch
from fault_tolerance.errors import InfeasibleBounds, IntolerableFailure, InvalidInput
from fault_tolerance.model.arm_spec import arm_of
from fault_tolerance.model.planar import (
    full_turn,
    planar_chain,
    reach_2r,
    require_planar_chain,
    rigid_pair,
)

OBJECTIVES = ("ftw-area", "jvj", "rcn")
VARY = ("limits", "links,limits")
#: Smallest share of the total length one link may have when links vary.
MIN_LINK_SHARE = 0.15
#: Smallest half-width of an artificial range [rad].
MIN_HALF_WIDTH = 0.2
#: Coarse workspace settings of the search (the chosen design is evaluated at ``grid``).
SEARCH_GRID, SEARCH_SAMPLES = 41, 16
#: Designs per chunk of a search round.
PER_CHUNK = 8


def scaled_arm(arm, lengths):
    """A copy of a planar-chain arm with link lengths ``lengths`` [m] (placements scaled)."""
    from fault_tolerance.model.arm import Arm

    chain = planar_chain(arm)
    model = pin.Model(arm.model)
    ratio = np.asarray(lengths, dtype=float) / chain.lengths
    for j in range(2, model.njoints):  # joint j's origin sits at the end of link j-1
        model.jointPlacements[j].translation = model.jointPlacements[j].translation * ratio[j - 2]
    f = model.frames[arm.frame_id]
    f.placement.translation = f.placement.translation * ratio[-1]
    model.frames[arm.frame_id] = f
    new = Arm(model, arm.tip, arm.task, name=arm.name, default_lockable=arm.default_lockable)
    if not np.allclose(planar_chain(new).lengths, lengths, atol=1e-9):
        raise InvalidInput(f"{arm.name}: its links cannot be rescaled by joint placements")
    return new


@dataclass(frozen=True)
class Task:
    """The circle task of a design: start ``x0`` [m], radius [m], rate ω [rad/s], duration [s]."""

    x0: tuple
    radius: float
    omega: float
    duration: float
    sign: float = 1.0

    def path(self):
        """The :class:`~fault_tolerance.simulation.paths.CirclePath`."""
        from fault_tolerance.simulation.paths import CirclePath

        return CirclePath(
            x0=np.asarray(self.x0),
            radius=self.radius,
            omega=self.omega,
            duration=self.duration,
            sign=self.sign,
        )


def default_task(arm) -> Task:
    """The catalog's circle for a shipped arm (paper Fig. 2 for planar_3r), else a scaled one."""
    from fault_tolerance.model.catalog import catalog

    entry = catalog().get(arm.source or "", {})
    if "x0" in entry and "path" in entry:
        p = entry["path"]
        return Task(tuple(entry["x0"]), p["radius"], p["omega"], p["duration"], p["sign"])
    L = float(require_planar_chain(arm).lengths.sum())
    return Task((0.35 * L / 1.5, 0.0), 0.1 * L / 1.5, 2 * np.pi, 1.0)


# -- one design ------------------------------------------------------------------------------


def limits_of(params: np.ndarray, phys: np.ndarray) -> np.ndarray:
    """Limits (3, 2) from ``params = [c_1, w_1, c_2, w_2, c_3, w_3]`` clipped to ``phys``."""
    c, w = params[0:6:2], params[1:6:2]
    return np.stack([np.maximum(c - w, phys[:, 0]), np.minimum(c + w, phys[:, 1])], 1)


def links_of(params: np.ndarray, total: float) -> np.ndarray | None:
    """Link lengths from the two share parameters (third share = 1 − the others), or None."""
    if len(params) <= 6:
        return None
    s = np.array([params[6], params[7], 1.0 - params[6] - params[7]])
    return s * total


def start_in_limits(arm, x0, A, lock_cols, samples: int = 720):
    """The configuration of minimum K on the self-motion at ``x0`` within ``A``, or None."""
    chain = require_planar_chain(arm)
    Av = np.stack(chain.v_limits(A[:, 0], A[:, 1]), 1)
    d = (np.asarray(x0, dtype=float) - chain.p0)[None]
    l1, l2, l3 = chain.lengths
    V = []
    for t in np.linspace(Av[2, 0], Av[2, 1], samples, endpoint=not full_turn(*Av[2])):
        M, g = rigid_pair(l2, l3, t)
        r = reach_2r(d, l1, M, Av[0, 0], Av[0, 1], Av[1, 0] + g, Av[1, 1] + g)
        V += [[r.va[b, 0], r.vb[b, 0] - g, t] for b in range(2) if r.ok[b, 0]]
    if not V:
        return None
    Q = chain.q_of_v(np.array(V))
    Q = np.clip(Q, A[:, 0], A[:, 1])  # (v − d) wraps by 2π at most at the range ends
    K = batch.square_sum_rcn(batch.jacobians(arm, Q), lock_cols)
    return Q[int(np.argmin(K))]


def task_indices(arm, A, task: Task, lock_cols, dt: float) -> dict:
    """Mean and max λ and K of JVJA along the task from :func:`start_in_limits`."""
    from fault_tolerance.simulation.simulate import simulate

    q0 = start_in_limits(arm, task.x0, A, lock_cols)
    if q0 is None:
        return {"feasible": False, "reason": "x0 is not reachable within the limits"}
    try:
        r = simulate(arm, task.path(), "jvja", q0=q0, lockable=lock_cols, dt=dt)
    except (
        InfeasibleBounds,
        IntolerableFailure,
    ) as err:  # one refused design, not the search's end
        return {"feasible": False, "reason": str(err).splitlines()[0][:200]}
    inside = bool(np.all((r.q >= A[:, 0] - 1e-9) & (r.q <= A[:, 1] + 1e-9)))
    return {
        "feasible": inside,
        "reason": "" if inside else "the run leaves the artificial limits",
        "jvj": float(np.mean(r.jvj)),
        "rcn": float(np.mean(r.K)),
        "rcn_max": float(np.max(r.K)),
        "q0": q0.tolist(),
    }


def evaluate(spec: dict, params: np.ndarray, *, final: bool = False) -> dict:
    """Objective record of one design (``final``: the fine workspace and dt of the result)."""
    from fault_tolerance.analysis.workspace.closed_form import failure_tolerant_workspace

    arm = arm_of(spec)
    phys = np.stack([arm.lower, arm.upper], 1)
    links = links_of(params, spec["total_length"])
    if links is not None:
        arm = scaled_arm(arm, links)
    A = limits_of(params, phys)
    cols = [arm.joint_names.index(j) for j in spec["lockable"]]
    out = {"params": params.tolist(), "limits": A.tolist()}
    if links is not None:
        out["links"] = links.tolist()
    if spec["objective"] == "ftw-area" or final:
        g = spec["grid"] if final else SEARCH_GRID
        s = None if final else SEARCH_SAMPLES
        ws = failure_tolerant_workspace(arm, A, cols, grid=g, samples=s, chunks=1)
        out["area_ftw"], out["area_pre"] = ws.area_ftw, ws.area_pre
        if final:
            out["workspace"] = ws
    if spec["objective"] != "ftw-area" or final:
        task = Task(**spec["task"])
        out.update(task_indices(arm, A, task, cols, 1e-3 if final else spec["search_dt"]))
    out["score"] = score(spec, out)
    return out


def score(spec: dict, rec: dict) -> float:
    """Smaller is better: −area, or the mean index (inf when infeasible or over rcn_max)."""
    if spec["objective"] == "ftw-area":
        return -rec["area_ftw"]
    if not rec.get("feasible"):
        return float("inf")
    if spec["rcn_max"] is not None and rec["rcn_max"] > spec["rcn_max"]:
        return float("inf")
    return rec[spec["objective"]]


def design_chunk(spec: dict, k: int) -> dict[str, np.ndarray]:
    """Scores and indices of the designs of chunk ``k`` of a search round (a sweep's compute)."""
    P = np.asarray(spec["candidates"])[k * PER_CHUNK : (k + 1) * PER_CHUNK]
    recs = [evaluate(spec, p) for p in P]
    nan = float("nan")
    return {
        "score": np.array([r["score"] for r in recs]),
        "area_ftw": np.array([r.get("area_ftw", nan) for r in recs]),
        "jvj": np.array([r.get("jvj", nan) for r in recs]),
        "rcn": np.array([r.get("rcn", nan) for r in recs]),
        "rcn_max": np.array([r.get("rcn_max", nan) for r in recs]),
        "feasible": np.array([bool(r.get("feasible", True)) for r in recs]),
    }
