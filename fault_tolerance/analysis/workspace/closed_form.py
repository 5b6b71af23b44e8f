"""Failure-tolerant workspace: the task points reachable before and after any single lock.

Definition (docs/MATH.md, "Failure-tolerant workspace"): artificial limits ``A = Π [lo_i, hi_i]``
hold the joints before a failure; ``W(A)`` are the task points reachable with ``q ∈ A``, and
``W_i(θ)`` those reachable with joint ``i`` locked at ``θ`` and the other joints moving within their
physical (URDF) limits. The failure-tolerant workspace is

    FTW(A) = W(A) ∩ ⋂_{i ∈ F} ⋂_{θ ∈ [lo_i, hi_i]} W_i(θ).

Two methods compute it on a grid of task points:

* ``planar-3r`` (a planar chain of three revolute joints, :mod:`.planar`): the lock conditions
  are exact, by closed-form 2R sub-chain reach and interval reasoning over θ (an annulus test
  with the exact range of the locked pair's length) where the two free joints turn fully, else θ
  is sampled at ``theta_samples`` angles with the 2R reach with limits exact at each. ``W(A)`` is
  the union over ``samples`` values of joint 3 in ``[lo_3, hi_3]`` of exact 2R reaches, an inner
  approximation missing at most a band ``l_3 Δq_3 / 2`` wide at its boundary.
* ``sampled`` (any other arm, planar or position task): :mod:`.workspace_sampled`.

At every point of ``W(A)`` the maps hold the smallest direction-averaged JVJA jump
(:func:`.batch.mean_jump`) and the smallest square-sum RCN ``K`` over the sampled self-motion
within ``A``.

Example:
    >>> import fault_tolerance as ft
    >>> from fault_tolerance.analysis.workspace.closed_form import failure_tolerant_workspace
    >>> ws = failure_tolerant_workspace(ft.load_arm("planar_3r"), grid=41, samples=24)
    >>> round(ws.area_ftw, 3), ws.area_pre > 7
    (0.0, True)
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.analysis import batch
from fault_tolerance.analysis.sweep import run
from fault_tolerance.analysis.workspace.result import DEFINITION, Workspace
from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm_spec import arm_of, robot_spec
from fault_tolerance.model.planar import (
    full_turn,
    planar_chain,
    reach_2r,
    require_planar_chain,
    rigid_pair,
)
from fault_tolerance.storage.budget import check_workspace

#: Default sample counts of the planar-3R method.
SAMPLES = 120  # joint-3 values for W(A) and the self-motion maps
THETA_SAMPLES = 181  # lock angles where the free joints do not turn fully
CHUNKS = 16


def parse_limits(arm, limits, deg: bool = False) -> np.ndarray:
    """Artificial limits as an (n, 2) array [rad]: ``None`` (physical), pairs, or ``"lo:hi,..."``.

    Raises:
        InvalidInput: wrong count, ``lo > hi``, or outside the physical limits.
    """
    phys = np.stack([arm.lower, arm.upper], 1)
    if limits is None:
        return phys
    if isinstance(limits, str):
        try:
            limits = [tuple(float(v) for v in p.split(":")) for p in limits.split(",")]
        except ValueError:
            raise InvalidInput(f"--limits must be lo:hi,... numbers, got '{limits}'") from None
    lim = np.asarray(limits, dtype=float)
    if lim.shape != (arm.n, 2):
        raise InvalidInput(
            f"limits need one lo:hi pair per joint ({arm.n}: {arm.joint_names}), got {lim.shape}"
        )
    if deg:  # angular joints only: prismatic joints' limits are metres
        from fault_tolerance.model.joint_limits import degrees_to_radians

        lim = degrees_to_radians(arm, lim)
    bad = ~np.isfinite(lim).all(1) | (lim[:, 0] > lim[:, 1])
    out = (lim[:, 0] < phys[:, 0] - 1e-9) | (lim[:, 1] > phys[:, 1] + 1e-9)
    if bad.any() or out.any():
        j = int(np.argmax(bad | out))
        raise InvalidInput(
            f"limits of {arm.joint_names[j]} [{lim[j, 0]:.6g}, {lim[j, 1]:.6g}] rad must be "
            f"finite, lo <= hi and within the physical [{phys[j, 0]:.6g}, {phys[j, 1]:.6g}] rad"
            + _degrees_hint(arm, lim, j, deg)
        )
    return lim


def _degrees_hint(arm, lim: np.ndarray, j: int, deg: bool) -> str:
    """The degrees hint of a refused angular joint ``j`` whose limits lie beyond a turn (> 2π)."""
    from fault_tolerance.model.joint_limits import DEGREES_OPTION_HINT, angular_columns

    degree_sized = np.isfinite(lim[j]).all() and np.abs(lim[j]).max() > 2 * np.pi
    return (
        f"; {DEGREES_OPTION_HINT}" if not deg and angular_columns(arm)[j] and degree_sized else ""
    )


def workspace_spec(arm, limits=None, lockable=None, *, grid=None, samples=None, **options) -> dict:
    """The JSON-able spec of a workspace sweep (method chosen from the arm's geometry)."""
    lim = parse_limits(arm, limits, options.pop("deg", False))
    lock = list(arm.default_lockable if lockable is None else lockable)
    for j in lock:
        arm.joint_index(j)
    if arm.redundancy < 1:
        raise InvalidInput(
            f"{arm.name} has no redundancy for task {'/'.join(arm.task)} (r = {arm.redundancy}): "
            "any lock loses the task, so its failure-tolerant workspace is empty"
        )
    chain = planar_chain(arm)
    spec = {"kind": "workspace", "robot": robot_spec(arm), "limits": lim.tolist()}
    spec["lockable"] = [arm.joint_names[arm.joint_index(j)] for j in lock]
    if chain is not None and arm.n == 3:
        spec["layout"] = "radius-strided"  # chunk of each point: radius_layout (in the hash)
        theta = int(options.pop("theta_samples", THETA_SAMPLES))
        chunks = int(options.pop("chunks", CHUNKS))
        if options:
            raise InvalidInput(f"unknown workspace option(s) {sorted(options)}")
        N = int(grid or 201)
        if N < 2 or samples is not None and int(samples) < 2 or theta < 2 or chunks < 1:
            raise InvalidInput("grid, samples and theta_samples must be >= 2, chunks >= 1")
        R = float(chain.lengths.sum())
        spec.update(method="planar-3r", grid=N, center=chain.p0.tolist(), half_width=R)
        spec.update(samples=int(samples or SAMPLES), theta_samples=theta, chunks=chunks)
        return spec
    from fault_tolerance.analysis.workspace.sampled import sampled_spec

    return sampled_spec(arm, spec, grid=grid, samples=samples, **options)


# -- the planar-3R method -------------------------------------------------------------------


def planar_grid(spec: dict) -> tuple[np.ndarray, np.ndarray, float]:
    """Cell centres ``(x, y)`` of an N x N grid centred on the base, and the cell side h [m]."""
    N, R = spec["grid"], spec["half_width"]
    h = 2.0 * R / N
    ax = [c + (np.arange(N) - (N - 1) / 2.0) * h for c in spec["center"]]
    return ax[0], ax[1], h


def radius_layout(N: int, chunks: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points inside the reach, ordered by exact integer radius key, and the chunk of each.

    Returns ``(order, keys, chunk)``: flat point indices (``ix * N + iy``) sorted by ``4 ρ² / h²``
    (exact integers), their keys, and their chunk. Points of one radius form a group (they share
    one index table, :func:`_index_table`); group ``g`` (in radius order) goes to chunk
    ``g mod chunks``, so every chunk holds radii from the whole range and all chunks cost about
    the same whatever the limits (contiguous radius bands cost up to 5x more in the middle than
    at the ends, leaving one of two workers idle at the end of a sweep).
    """
    i = 2 * np.arange(N) - (N - 1)  # 2 (x - c) / h, integers
    key = (i[:, None] ** 2 + i[None, :] ** 2).ravel()  # 4 ρ² / h², exact; flat index = ix * N + iy
    inside = np.flatnonzero(key <= N * N)  # ρ <= R
    order = inside[np.argsort(key[inside], kind="stable")]
    ks = key[order]
    group = np.cumsum(np.concatenate([[False], ks[1:] != ks[:-1]]))
    return order, ks, group % chunks


def _lock_exact(i: int, rho, phi, lengths, A) -> np.ndarray:
    """Joint i locks anywhere in ``A[i]`` and the other two turn fully: annulus tests, exact."""
    from fault_tolerance.model.planar import cos_range

    l1, l2, l3 = lengths
    tol = 1e-12
    if i == 0:  # base of the 2R (l2, l3) on the circle l1 e(θ), θ ∈ A_1
        cmin, cmax = cos_range(A[0, 0] - phi, A[0, 1] - phi)
        dmax = np.sqrt(np.maximum(rho**2 + l1**2 - 2 * rho * l1 * cmin, 0))
        dmin = np.sqrt(np.maximum(rho**2 + l1**2 - 2 * rho * l1 * cmax, 0))
        return (dmin >= abs(l2 - l3) - tol) & (dmax <= l2 + l3 + tol)
    la, lb, lo = (l1, l2, l3) if i == 1 else (l2, l3, l1)  # locked pair (la, lb), other link lo
    cmin, cmax = cos_range(A[i, 0], A[i, 1])
    Lmin = np.sqrt(max(la**2 + lb**2 + 2 * la * lb * cmin, 0.0))
    Lmax = np.sqrt(max(la**2 + lb**2 + 2 * la * lb * cmax, 0.0))
    return (rho <= Lmin + lo + tol) & (rho >= max(abs(lo - Lmin), abs(lo - Lmax)) - tol)


def _lock_sampled(i: int, d, lengths, A, P, T: int) -> np.ndarray:
    """Joint i locks at T angles of ``A[i]`` (ends included); exact 2R reach with limits at each."""
    l1, l2, l3 = lengths
    ok = np.ones(len(d), dtype=bool)
    for th in np.linspace(A[i, 0], A[i, 1], T):
        if i == 0:
            base = l1 * np.array([np.cos(th), np.sin(th)])
            r = reach_2r(d - base, l2, l3, th + P[1, 0], th + P[1, 1], P[2, 0], P[2, 1])
        elif i == 1:
            L, g = rigid_pair(l1, l2, th)
            r = reach_2r(d, L, l3, P[0, 0] + g, P[0, 1] + g, P[2, 0] + th - g, P[2, 1] + th - g)
        else:
            M, g = rigid_pair(l2, l3, th)
            r = reach_2r(d, l1, M, P[0, 0], P[0, 1], P[1, 0] + g, P[1, 1] + g)
        ok &= r.hit
    return ok


def _joint3_samples(spec, A) -> np.ndarray:
    """The ``samples`` values of joint 3 (shifted) in ``A[2]`` (a full turn without its end)."""
    S = spec["samples"]
    return np.linspace(A[2, 0], A[2, 1], S, endpoint=not full_turn(A[2, 0], A[2, 1]))


def _reach_at(chain, d, t, A):
    """2R reach of ``d`` by links (l1, |l2 + l3 e(t)|) with joint 3 at ``t``, in A; v2 per branch."""
    l1, l2, l3 = chain.lengths
    M, g = rigid_pair(l2, l3, t)
    r = reach_2r(d, l1, M, A[0, 0], A[0, 1], A[1, 0] + g, A[1, 1] + g)
    return r.ok, r.vb - g  # vb - g = v2


def _index_table(arm, chain, lock_cols, v2, v3, valid):
    """Mean JVJA jump and K at (q1 = 0, q2, q3) for the valid samples; NaN elsewhere.

    A planar chain's indices do not depend on q1 (the whole arm turns with it), so points at one
    radius share one table.
    """
    jump = np.full(valid.shape, np.nan)
    K = np.full(valid.shape, np.nan)
    where = np.nonzero(valid)
    if not len(where[0]):
        return jump, K
    V = np.zeros((len(where[0]), 3))
    V[:, 0] = chain.offsets[0]
    V[:, 1] = v2[where]
    V[:, 2] = np.broadcast_to(v3[:, None, None], valid.shape)[where]
    Js = batch.jacobians(arm, chain.q_of_v(V))
    jump[where] = batch.mean_jump(Js, lock_cols, intolerable="nan")
    K[where] = batch.square_sum_rcn(Js, lock_cols)
    return jump, K


def planar_chunk(spec: dict, k: int) -> dict[str, np.ndarray]:
    """Masks and maps of the points in chunk ``k`` of a planar-3R spec (a sweep's compute)."""
    arm = arm_of(spec)
    chain = require_planar_chain(arm)
    order, keys, chunk = radius_layout(spec["grid"], spec["chunks"])
    mine = chunk == k
    idx, keys = order[mine], keys[mine]
    x, y, h = planar_grid(spec)
    N = spec["grid"]
    d = np.stack([x[idx // N], y[idx % N]], 1) - chain.p0
    rho, phi = np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])
    A = np.stack(chain.v_limits(*np.asarray(spec["limits"]).T), 1)
    P = np.stack(chain.v_limits(arm.lower, arm.upper), 1)
    lock_cols = [arm.joint_names.index(j) for j in spec["lockable"]]
    locks = []
    for i in lock_cols:
        free = [j for j in range(3) if j != i]
        if all(full_turn(*P[j]) for j in free):
            locks.append(_lock_exact(i, rho, phi, chain.lengths, A))
        else:
            locks.append(_lock_sampled(i, d, chain.lengths, A, P, spec["theta_samples"]))
    pre, jmin, kmin = _self_motion_minima(spec, arm, chain, d, rho, keys, A, lock_cols)
    return {
        "index": idx,
        "pre": pre,
        "locks": np.array(locks).reshape(len(lock_cols), len(idx)),
        "jump": jmin,
        "rcn": kmin,
    }


def _self_motion_minima(spec, arm, chain, d, rho, keys, A, lock_cols):
    """W(A) membership and the smallest jump and K over the joint-3 samples, per point.

    The indices of a planar chain depend on the radius only, so one table per radius (its
    group's first point) serves all its points; the samples are then visited one by one with
    arrays of one value per point, never (samples, 2, points) ones.
    """
    v3 = _joint3_samples(spec, A)
    _, first, inv = np.unique(keys, True, True)
    rep_v2 = np.zeros((len(v3), 2, len(first)))
    for s, t in enumerate(v3):
        rep_v2[s] = _reach_at(chain, d[first], t, A)[1]
    rep_ok = np.array([_ik_real(chain, rho[first], t, A) for t in v3]).reshape(len(v3), 2, -1)
    jt, Kt = _index_table(arm, chain, lock_cols, rep_v2, v3, rep_ok)
    pre = np.zeros(len(d), dtype=bool)
    jmin = np.full(len(d), np.nan)
    kmin = np.full(len(d), np.nan)
    with np.errstate(all="ignore"):
        for s, t in enumerate(v3):
            ok = _reach_at(chain, d, t, A)[0]
            for b in (0, 1):
                pre |= ok[b]
                np.fmin(jmin, np.where(ok[b], jt[s, b, inv], np.nan), out=jmin)
                np.fmin(kmin, np.where(ok[b], Kt[s, b, inv], np.nan), out=kmin)
    return pre, jmin, kmin


def _ik_real(chain, rho, v3, A) -> np.ndarray:
    """Both branches of the 2R (l1, |l2 + l3 e(v3)|) reach radius ρ with v2 in A (shape (2, U))."""
    l1, l2, l3 = chain.lengths
    M, g = rigid_pair(l2, l3, v3)
    r = reach_2r(np.stack([rho, np.zeros_like(rho)], 1), l1, M, 0.0, 7.0, A[1, 0] + g, A[1, 1] + g)
    return r.ok


def assemble_planar(spec: dict, chunks: list[dict]) -> Workspace:
    """The :class:`Workspace` of a planar-3R spec from its chunks."""
    N = spec["grid"]
    f = len(spec["lockable"])
    pre = np.zeros(N * N, dtype=bool)
    locks = np.zeros((f, N * N), dtype=bool)
    jump = np.full(N * N, np.nan)
    K = np.full(N * N, np.nan)
    for c in chunks:
        i = c["index"]
        pre[i], locks[:, i], jump[i], K[i] = c["pre"], c["locks"], c["jump"], c["rcn"]
    x, y, h = planar_grid(spec)
    ftw = pre & locks.all(axis=0)
    S, A = spec["samples"], np.asarray(spec["limits"])
    chain = require_planar_chain(arm_of(spec))
    band = chain.lengths[2] * (A[2, 1] - A[2, 0]) / max(S - 1, 1) / 2
    error = (
        f"grid cell {h:.4g} m (area error up to about the boundary length x {h / 2:.3g} m); "
        f"W(A) samples joint 3 at {S} values, missing at most a band {band:.3g} m wide at its "
        "boundary; lock conditions exact where the two free joints turn fully (URDF range within "
        f"1e-4 rad of 2π), else at {spec['theta_samples']} lock angles"
    )
    shape = (N, N)
    return Workspace(
        spec=spec,
        axes=(x, y),
        pre=pre.reshape(shape),
        ftw=ftw.reshape(shape),
        locks=locks.reshape((f, *shape)),
        jump=jump.reshape(shape),
        rcn=K.reshape(shape),
        cell=h * h,
        definition=DEFINITION,
        error=error,
    )


def failure_tolerant_workspace(
    arm,
    limits=None,
    lockable=None,
    *,
    workers=0,
    scheduler=None,
    folder=None,
    progress=False,
    **options,
) -> Workspace:
    """Compute the failure-tolerant workspace of ``arm`` (module doc), serially or on Dask.

    Args:
        arm: An :class:`~fault_tolerance.Arm` (planar task for the exact method; position task or
            a non-planar arm for the sampled one).
        limits: Artificial limits, (n, 2) [rad] or ``"lo:hi,..."`` (``deg=True`` for degrees);
            default: the physical limits (no artificial limits).
        lockable: Joints that may lock (default: the arm's default lockable joints).
        workers: 0 serial, 1 an in-process Dask worker, N > 1 a local cluster of N processes
            (:func:`.sweep.run`).
        scheduler: Address of a running Dask scheduler (instead of ``workers``).
        folder: Output folder for the finished chunks (resumable), or ``None``.
        progress: Show a progress bar.
        **options: ``grid``, ``samples``, ``theta_samples``, ``chunks``, ``deg`` (and, for the
            sampled method, ``seed``).
    """
    spec = workspace_spec(arm, limits, lockable, **options)
    from fault_tolerance.analysis.workspace import sampled

    f, points = len(spec["lockable"]), spec["grid"] ** len(spec["center"])
    if spec["method"] == "planar-3r":
        count, compute, assemble = spec["chunks"], planar_chunk, assemble_planar
        bound = points * (25 + f)  # index, jump, rcn (8 bytes), pre (1), locks (f): every point
    else:
        per = -(-int(spec["samples"]) // sampled.CHUNK_SAMPLES)
        count = per * (1 + f * int(spec["theta_samples"]))
        compute, assemble, bound = sampled.sampled_chunk, sampled.assemble_sampled, points * 17
    check_workspace(spec, count)  # every size refused before any chunk runs
    chunks = run(
        compute,
        spec,
        count if spec["method"] == "planar-3r" else sampled.n_chunks(spec),
        folder=folder,
        workers=workers,
        scheduler=scheduler,
        progress=progress,
        desc="workspace",
        chunk_bytes=bound + (1 << 16),
    )
    return assemble(spec, chunks)
