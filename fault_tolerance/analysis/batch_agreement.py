"""How closely the batched API (:mod:`.batch`) agrees with the scalar API, measured.

:func:`batch_agreement` draws rows of two kinds on an arm, solves them both ways and returns the
largest relative difference of every quantity:

* *random* rows: configurations drawn inside the joint limits (``Arm.random_q``), task
  velocities from a standard normal;
* *ill-conditioned* rows: configurations ``q = ε·g`` around the stretched-out ``q = 0`` with
  ``g`` standard normal and ``ε`` log-uniform in ``[1e-7, 1e-1]``, so ``σ_min(J)`` spans both
  sides of the damping threshold ``SIGMA_EPS`` and pivots of ``N[S, S]`` come near ``PIVOT_EPS``.

The relative difference of a row is ``‖v_batch − v_scalar‖₂ / ‖v_scalar‖₂`` for the rates and
``|·|`` for λ (eq. 9/10) and every ``k_S`` (eq. 15); rows with an intolerable scenario (where
JVJA and λ are not defined) are left out of JVJA and λ. docs/batch.md gives the numbers measured
on the shipped arms and the Panda (``scripts/batch_agreement.py``); :data:`BATCH_RTOL` is the
tolerance the tests hold the batched API to.
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.analysis import batch
from fault_tolerance.errors import IntolerableFailure
from fault_tolerance.resolution.indices import jvj, rcn
from fault_tolerance.resolution.resolvers import resolve

#: Largest relative difference of the batched API from the scalar API the tests accept.
BATCH_RTOL = 1e-10


def _rows(arm, rng, random_rows: int, ill_rows: int) -> tuple[np.ndarray, np.ndarray]:
    """``(Q, kind)``: random configurations, then ill-conditioned ones near ``q = 0``."""
    Q_random = np.array([arm.random_q(rng) for _ in range(random_rows)]).reshape(-1, arm.n)
    eps = 10.0 ** rng.uniform(-7.0, -1.0, ill_rows)
    Q_ill = rng.normal(size=(ill_rows, arm.n)) * eps[:, None]
    kind = np.array(["random"] * random_rows + ["ill"] * ill_rows)
    return np.vstack([Q_random, Q_ill]), kind


def _tolerable(Js, m: int, n: int, lockable) -> np.ndarray:
    ok = []
    for J in Js:
        try:
            jvj(J, np.zeros(m), np.zeros(n), lockable)
            ok.append(True)
        except IntolerableFailure:
            ok.append(False)
    return np.array(ok, dtype=bool)


def _rel(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise relative difference ``‖a − b‖ / ‖b‖`` (rows of vectors or scalars)."""
    a, b = np.atleast_1d(a), np.atleast_1d(b)
    if a.ndim == 1:
        return np.abs(a - b) / np.maximum(np.abs(b), 1e-300)
    return np.linalg.norm(a - b, axis=1) / np.maximum(np.linalg.norm(b, axis=1), 1e-300)


def batch_agreement(
    arm, lockable, *, random_rows: int = 1000, ill_rows: int = 1000, seed: int = 0
) -> dict[str, dict[str, float]]:
    """Largest relative batched-vs-scalar difference, by row kind (``random``, ``ill``, ``all``).

    Keys of each entry: ``lnva``, ``jvja``, ``jvja_continuation`` (rates), ``jvj`` (λ of the JVJA rates), ``rcn``
    (every ``k_S``), ``rows`` (rows solved), ``sigma_min`` (smallest σ_min(J) among them).
    """
    rng = np.random.default_rng(seed)
    Q, kind = _rows(arm, rng, random_rows, ill_rows)
    Js = batch.jacobians(arm, Q)
    xd = rng.normal(size=(len(Q), arm.m))
    ok = _tolerable(Js, arm.m, arm.n, lockable)
    rel = {
        "lnva": _rel(batch.resolve("lnva", Js, xd), np.array([resolve("lnva", J, x) for J, x in zip(Js, xd, strict=True)])),
    }  # fmt: skip
    qd = batch.resolve("jvja", Js[ok], xd[ok], lockable)
    ref = np.array([resolve("jvja", J, x, lockable) for J, x in zip(Js[ok], xd[ok], strict=True)])
    rel["jvja"] = _full(_rel(qd, ref), ok)
    qc = batch.resolve("jvja", Js[ok], xd[ok], lockable, response="continuation")
    rc = [resolve("jvja", J, x, lockable, response="continuation") for J, x in zip(Js[ok], xd[ok], strict=True)]  # fmt: skip
    rel["jvja_continuation"] = _full(_rel(qc, np.array(rc)), ok)
    lam = batch.jvj(Js[ok], xd[ok], qd, lockable)
    lref = [jvj(J, x, v, lockable) for J, x, v in zip(Js[ok], xd[ok], ref, strict=True)]
    rel["jvj"] = _full(_rel(lam, np.array(lref)), ok)
    k = batch.rcn(Js[ok], lockable)
    kref = np.array([rcn(J, lockable) for J in Js[ok]])
    rel["rcn"] = _full(np.max(np.abs(k - kref) / np.maximum(kref, 1e-300), axis=1), ok)
    sig = np.array([np.linalg.svd(J, compute_uv=False)[-1] for J in Js])
    out = {}
    for label, mask in (("random", kind == "random"), ("ill", kind == "ill"), ("all", kind != "")):
        out[label] = {name: float(np.nanmax(r[mask], initial=0.0)) for name, r in rel.items()}
        out[label]["rows"] = float(mask.sum())
        out[label]["sigma_min"] = float(sig[mask].min()) if mask.any() else float("nan")
    return out


def _full(values: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """``values`` of the tolerable rows in place, NaN on the others."""
    out = np.full(len(ok), np.nan)
    out[ok] = values
    return out
