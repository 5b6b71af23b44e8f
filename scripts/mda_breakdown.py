"""Where the compiled MDA step's time goes, part by part, on one benchmark arm.

Times, in one process and on the benchmark's pool of configurations, the whole MDA, JVJA and
LNVA steps of the Controller (LNVA's is the part MDA shares), the Jacobian, and ∇K's parts
inside compiled loops (no call overhead): the eigenpairs of ``G = J Jᵀ`` and the two secular
roots of every scenario (eq. 15, K3). It explains the ``mda_over_jvja`` row of
``fault-tolerance bench`` (docs/mda.md) and prints what that row's target (≤ 2) leaves for ∇K::

    python scripts/mda_breakdown.py panda_pose panda_position spatial_4r
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pinocchio as pin

import fault_tolerance as ft
from fault_tolerance.bench.cases import ARMS, make_case
from fault_tolerance.numerics.fast.dense import gram_into
from fault_tolerance.numerics.fast.rank_one_eigen import LANE_ROWS, all_extremes, eigenpairs
from fault_tolerance.numerics.fast.small_eigen import njit

REPS = 20000


def call_times_us(fn, args, reps=REPS) -> np.ndarray:
    """Wall time of each of ``reps`` calls ``fn(*args[i])``, cycling over ``args`` [µs].

    The first 50 calls run untimed.
    """
    for a in args[:50]:
        fn(*a)
    ts = np.empty(reps)
    for r in range(reps):
        a = args[r % len(args)]
        t = time.perf_counter()
        fn(*a)
        ts[r] = time.perf_counter() - t
    return ts * 1e6


def median_us(fn, args, reps=REPS) -> float:
    """Median wall time of ``fn(*args[i])`` over ``reps`` calls [µs]."""
    return float(np.median(call_times_us(fn, args, reps)))


@njit
def _eigen_loop(Js, reps):  # pragma: no cover - numba
    """``reps`` Gram matrices and their eigenpairs (the first part of ∇K), cycling over ``Js``."""
    k, m, n = Js.shape
    A, Vt, d, w = np.empty((m, m)), np.empty((m, m)), np.empty(m), np.empty(2 * m)
    acc = 0.0
    for t in range(reps):
        gram_into(Js[t % k], A)
        eigenpairs(A, m, Vt, d, w)
        acc += d[0]
    return acc


@njit
def _roots_loop(Js, cols, reps):  # pragma: no cover - numba
    """``reps`` times: ``Z = Vt J`` and both secular roots of every scenario, side by side
    (:func:`all_extremes`, as the kernel; ``G``'s eigenpairs given)."""
    k, m, n = Js.shape
    f = cols.shape[0]
    A, Vt, d, w = np.empty((m, m)), np.empty((m, m)), np.empty(m), np.empty(2 * m)
    Zs, ds = np.empty((k, m, n)), np.empty((k, m))
    for t in range(k):
        gram_into(Js[t], A)
        eigenpairs(A, m, Vt, d, w)
        Zs[t], ds[t] = Vt @ Js[t], d
    U2, X, lam = np.empty((m, f)), np.empty((LANE_ROWS + 1, max(f, m))), np.empty((3, f))
    acc = 0.0
    for t in range(reps):
        all_extremes(ds[t % k], Zs[t % k], cols, m, U2, X, lam)
        acc += lam[0, 0] + lam[1, 0]
    return acc


def in_loop_us(fn, *args) -> float:
    """Wall time of one iteration of a compiled loop [µs] (compiled first, median of 5 runs)."""
    fn(*args[:-1], 10)
    runs = []
    for _ in range(5):
        t = time.perf_counter()
        fn(*args[:-1], args[-1])
        runs.append((time.perf_counter() - t) / args[-1] * 1e6)
    return float(np.median(runs))


def reference_gap(case, count=100) -> float:
    """Largest ``|MDA step − ft.resolve('mda')| / max(1, |q̇|)`` over ``count`` pool samples."""
    ctrl, arm, worst = case.ctrl, case.arm, 0.0
    for q, xd in list(zip(case.qs, case.xds, strict=True))[:count]:
        got = ctrl.mda(q, xd).copy()
        ref = ft.resolve("mda", arm.jacobian(q), xd, lockable=ctrl.scenarios, arm=arm, q=q)
        worst = max(worst, float(np.abs(got - ref).max() / max(1.0, np.abs(ref).max())))
    return worst


def breakdown(case) -> dict[str, float]:
    """The parts of the MDA step of a bench case (:func:`make_case`) [µs]."""
    ctrl, cw = case.ctrl, case.ctrl.workspace
    Js = np.array(
        [pin.computeFrameJacobian(cw.model, cw.data, q, cw.frame_id, pin.LOCAL_WORLD_ALIGNED)[cw.rows]
         for q in case.qs]
    )  # fmt: skip
    cols = np.asarray(cw.scenarios.columns, dtype=np.int64)
    return {
        "jacobian": median_us(ctrl.jacobian, [(q,) for q in case.qs]),
        "lnva step": median_us(ctrl.lnva, case.qxo),
        "jvja step": median_us(ctrl.jvja, case.qxo),
        "mda step": median_us(ctrl.mda, case.qxo),
        "eigenpairs of G (in a loop)": in_loop_us(_eigen_loop, Js, 20000),
        f"{2 * len(cols)} secular roots (in a loop)": in_loop_us(_roots_loop, Js, cols, 20000),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("arms", nargs="+", choices=sorted(ARMS), metavar="ARM",
                        help="benchmark arms, e.g. panda_pose spatial_4r")  # fmt: skip
    for key in parser.parse_args().arms:
        case = make_case(key)
        parts = breakdown(case)
        print(f"{key}: " + ", ".join(f"{k} {v:.2f} µs" for k, v in parts.items())
              + f"; MDA / JVJA {parts['mda step'] / parts['jvja step']:.2f}"
              + f"; MDA vs ft.resolve('mda') {reference_gap(case):.1e}")  # fmt: skip
        print(f"  {key}: {budget(parts)}")


def budget(parts: dict[str, float]) -> str:
    """What the bench target (MDA ≤ 2 × JVJA) leaves for ∇K, against ∇K's two fixed parts.

    The MDA step is the LNVA step (Jacobian, certificate, least-norm rates) plus ∇K and the null
    step, so ``2 · jvja − lnva`` is all ∇K may take; the eigenpairs of ``G`` and the secular
    roots are work every exact ∇K of this design does before a single eigenvector.
    """
    left = 2.0 * parts["jvja step"] - parts["lnva step"]
    fixed = sum(v for k, v in parts.items() if k.endswith("(in a loop)"))
    return (f"the target leaves {left:.2f} µs for ∇K (2·jvja − lnva); its eigenpairs and roots "
            f"take {fixed:.2f} µs; ∇K now takes {parts['mda step'] - parts['lnva step']:.2f} µs")  # fmt: skip


if __name__ == "__main__":
    main()
