"""The sampled failure-tolerant workspace, for arms without a closed form (any URDF arm).

Task points are the cells of a grid (N per linear task row) over the cube of half-width ``R``
around the first joint, ``R`` the sum of the distances between consecutive joint origins and the
tip (rigid, so an upper bound of the reach; from Pinocchio's placements). Pinocchio's forward
kinematics at random configurations marks the cells they land in:

* ``W(A)``: ``samples`` configurations uniform in the artificial limits A;
* ``W_i(θ)``: for each lockable joint i, ``theta_samples`` lock angles θ over ``[lo_i, hi_i]``
  (ends included), each with ``samples`` configurations of the other joints uniform in their
  physical limits.

A cell is reachable when a sample lands in it: an inner approximation that misses thin parts and
boundary cells a sample did not hit; the lock angles are sampled, so a failure between two of them
is not checked. The error is stated with the result (cell size, samples per reachable cell).
Samples are seeded by chunk, so results do not depend on the number of workers.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from fault_tolerance.analysis import batch
from fault_tolerance.analysis.workspace.result import DEFINITION, Workspace
from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm_spec import arm_of

#: Samples per chunk (FK evaluations); a set of ``samples`` splits into chunks of this size.
CHUNK_SAMPLES = 10000


def _reach_bound(arm) -> tuple[np.ndarray, float]:
    """Centre (first joint origin) and an upper bound of the reach [m] from Pinocchio placements."""
    q = arm.neutral()
    pin.framesForwardKinematics(arm.model, arm.data, q)
    pts = [arm.data.oMi[j].translation.copy() for j in range(1, arm.model.njoints)]
    pts.append(arm.data.oMf[arm.frame_id].translation.copy())
    R = float(np.linalg.norm(np.diff(np.array(pts), axis=0), axis=1).sum())
    return pts[0], R


def sampled_spec(arm, spec: dict, *, grid=None, samples=None, **options) -> dict:
    """Complete a workspace spec for the sampled method (module doc)."""
    rows = [r for r in arm.task]
    if any(r.startswith("r") for r in rows) or len(rows) not in (2, 3):
        raise InvalidInput(
            f"the workspace needs a planar or position task (2 or 3 linear rows); {arm.name} has "
            f"task rows {rows}; pass task='position' (--task position) or 'planar'"
        )
    theta = int(options.pop("theta_samples", 7))
    seed = int(options.pop("seed", 0))
    if options.pop("chunks", None) is not None:
        raise InvalidInput(
            f"chunks applies to the planar-3R method; the sampled method ({arm.name}) chunks by "
            f"{CHUNK_SAMPLES} configurations"
        )
    if options:
        raise InvalidInput(f"unknown workspace option(s) {sorted(options)}")
    m = len(rows)
    N = int(grid or (101 if m == 2 else 24))
    n = int(samples or (40000 if m == 3 else 20000))
    if N < 2 or n < 1 or theta < 2:
        raise InvalidInput("grid >= 2, samples >= 1 and theta_samples >= 2 are required")
    c, R = _reach_bound(arm)
    centre = c[arm.rows].tolist()
    spec.update(method="sampled", grid=N, center=centre, half_width=R, samples=n)
    spec.update(theta_samples=theta, seed=seed)
    return spec


def _jobs(spec: dict) -> list[tuple]:
    per = -(-spec["samples"] // CHUNK_SAMPLES)
    jobs = [("pre", -1, -1, c) for c in range(per)]
    for i in range(len(spec["lockable"])):
        jobs += [("lock", i, t, c) for t in range(spec["theta_samples"]) for c in range(per)]
    return jobs


def n_chunks(spec: dict) -> int:
    """Number of chunks of a sampled spec."""
    return len(_jobs(spec))


def grid_axes(spec: dict) -> tuple[tuple[np.ndarray, ...], float]:
    """Cell centres per task row and the cell side [m]."""
    N, R = spec["grid"], spec["half_width"]
    h = 2.0 * R / N
    return tuple(c + (np.arange(N) - (N - 1) / 2.0) * h for c in spec["center"]), h


def _cells(spec: dict, X: np.ndarray) -> np.ndarray:
    """Flat cell index of task points X (B, m); -1 outside the grid."""
    N, R = spec["grid"], spec["half_width"]
    h = 2.0 * R / N
    ij = np.floor((X - np.asarray(spec["center"]) + R) / h).astype(int)
    inside = np.all((ij >= 0) & (ij < N), axis=1)
    flat = np.ravel_multi_index(tuple(np.clip(ij, 0, N - 1).T), (N,) * X.shape[1])
    return np.where(inside, flat, -1)


def _positions(arm, Q: np.ndarray) -> np.ndarray:
    model, data, fid, rows = arm.model, arm.data, arm.frame_id, arm.rows
    X = np.empty((len(Q), len(rows)))
    for b, q in enumerate(Q):
        pin.framesForwardKinematics(model, data, q)
        X[b] = data.oMf[fid].translation[rows]
    return X


def _uniform(rng, lo, hi, size) -> np.ndarray:
    lo = np.where(np.isfinite(lo), lo, -np.pi)
    hi = np.where(np.isfinite(hi), hi, np.pi)
    return rng.uniform(lo, hi, size=(size, len(lo)))


def sampled_chunk(spec: dict, k: int) -> dict[str, np.ndarray]:
    """Cells hit by one chunk of samples, and (W(A) chunks) the smallest indices per cell."""
    return sampled_cells(arm_of(spec), spec, k)


def sampled_in_process(arm, spec: dict) -> Workspace:
    """The sampled workspace of ``spec`` for an arm built in this process, serially.

    For an arm with no file to rebuild it from (a DH candidate): the same cells as a sweep's.
    """
    return assemble_sampled(spec, [sampled_cells(arm, spec, k) for k in range(n_chunks(spec))])


def sampled_cells(arm, spec: dict, k: int) -> dict[str, np.ndarray]:
    """Chunk ``k`` of :func:`sampled_chunk` for ``arm`` (the arm of ``spec``)."""
    kind, i, t, c = _jobs(spec)[k]
    rng = np.random.default_rng([spec["seed"], k])
    size = min(CHUNK_SAMPLES, spec["samples"] - c * CHUNK_SAMPLES)
    V = spec["grid"] ** len(spec["center"])
    A = np.asarray(spec["limits"])
    if kind == "pre":
        Q = _uniform(rng, A[:, 0], A[:, 1], size)
    else:
        col = arm.joint_names.index(spec["lockable"][i])
        Q = _uniform(rng, arm.lower, arm.upper, size)
        Q[:, col] = np.linspace(A[col, 0], A[col, 1], spec["theta_samples"])[t]
    cells = _cells(spec, _positions(arm, Q))
    hit = np.zeros(V, dtype=bool)
    hit[cells[cells >= 0]] = True
    out = {"hit": hit}
    if kind == "pre":
        cols = [arm.joint_names.index(j) for j in spec["lockable"]]
        Js = batch.jacobians(arm, Q)
        jump = np.full(V, np.inf)
        K = np.full(V, np.inf)
        ok = cells >= 0
        with np.errstate(invalid="ignore"):
            np.fmin.at(jump, cells[ok], batch.mean_jump(Js[ok], cols, intolerable="nan"))
            np.fmin.at(K, cells[ok], batch.square_sum_rcn(Js[ok], cols))
        out.update(jump=jump, rcn=K)
    return out


def assemble_sampled(spec: dict, chunks: list[dict]) -> Workspace:
    """The :class:`Workspace` of a sampled spec from its chunks (OR, AND and min: order-free)."""
    jobs = _jobs(spec)
    axes, h = grid_axes(spec)
    shape = (spec["grid"],) * len(axes)
    V = int(np.prod(shape))
    f, T = len(spec["lockable"]), spec["theta_samples"]
    pre = np.zeros(V, dtype=bool)
    jump = np.full(V, np.inf)
    K = np.full(V, np.inf)
    hits = np.zeros((f, T, V), dtype=bool)
    for (kind, i, t, _), c in zip(jobs, chunks, strict=True):
        if kind == "pre":
            pre |= c["hit"]
            jump = np.fmin(jump, c["jump"])
            K = np.fmin(K, c["rcn"])
        else:
            hits[i, t] |= c["hit"]
    locks = hits.all(axis=1)
    jump[~np.isfinite(jump)] = np.nan
    K[~np.isfinite(K)] = np.nan
    per_cell = spec["samples"] / max(int(pre.sum()), 1)
    error = (
        f"sampled: cells of {h:.4g} m; {spec['samples']} samples per set (about {per_cell:.1f} "
        f"per reachable cell), so cells no sample hit count unreachable (inner approximation); "
        f"{T} lock angles per joint, failures between them are not checked"
    )
    return Workspace(
        spec=spec,
        axes=axes,
        pre=pre.reshape(shape),
        ftw=(pre & locks.all(axis=0)).reshape(shape),
        locks=locks.reshape((f, *shape)),
        jump=jump.reshape(shape),
        rcn=K.reshape(shape),
        cell=h ** len(axes),
        definition=DEFINITION,
        error=error,
    )
