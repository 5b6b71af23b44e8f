"""The batched API's LNVA / JVJA rates from the Controller's compiled step kernel, row by row.

:func:`single_rows` runs :func:`.single_kernel.packed_step_kernel` (LNVA, single-joint JVJA: the
very step of :class:`~fault_tolerance.control.controller.Controller`, in its workspace layout,
:func:`single_workspace`) over the rows of a stack of Jacobians ``Js`` (B, m, n), into a (B, n)
output with a status per row. A row it refuses (status ≠ 0) is left to the caller,
:func:`fault_tolerance.analysis.batch.resolve`, which redoes those rows with its stacked NumPy code (damped,
NaN or raising as without numba):

* 1: no certificate of ``σ_min(J) ≥ SIGMA_EPS`` (damping may be needed), or not finite;
* 2: a pivot ``N_ii`` below :data:`THRESHOLD` = 2·``PIVOT_TOL`` (the kernel and the NumPy code
  round ``N`` differently, ~1e-13, so a row near ``PIVOT_TOL`` is decided by the NumPy code);
* 4: the Cholesky route's error estimate exceeds :data:`ACCURACY` (ill-conditioned ``J J^T``
  or a small pivot: the two routes could differ by more than 1e-9, :func:`_accurate`).

Multi-joint scenarios are not run here (no cheap error estimate for ``λ_min(N[S, S])`` yet).

Example:
    >>> import numpy as np
    >>> from fault_tolerance.analysis.fast import batch as batch_kernel
    >>> from fault_tolerance.resolution.scenarios import scenarios
    >>> Js = np.array([[[1.0, 0.5, 0.2]], [[0.0, 0.0, 0.0]]])        # B = 2, m = 1, n = 3
    >>> out, status = batch_kernel.rates(Js, np.ones((2, 1)), scenarios([0, 1], 3, r=2))
    >>> status.tolist()                                               # row 1: no certificate
    [0, 1]
"""

from __future__ import annotations

import math

import numpy as np

from fault_tolerance.control.fast.step import _views, packed_step_kernel, workspace_shape
from fault_tolerance.control.lapack_steps import TRACE_MAX
from fault_tolerance.fast_cache import njit as _njit
from fault_tolerance.numerics.fast.dense import gram_factor, trace_inverse
from fault_tolerance.numerics.fast.sample_dense import _spectra
from fault_tolerance.numerics.linalg import PIVOT_TOL, RANK_RTOL
from fault_tolerance.resolution.indices import RCN_MAX
from fault_tolerance.resolution.scenarios import Scenarios

#: Pivots of ``N[S, S]`` below this leave the kernel for the NumPy code (which decides at
#: ``PIVOT_TOL`` whether the scenario is intolerable).
THRESHOLD = 2.0 * PIVOT_TOL
#: Largest estimated difference (relative) from the NumPy code for a row the kernel keeps.
ACCURACY = 1e-11
EPS = float(np.finfo(float).eps)
#: Largest ``k_S`` the compiled RCN keeps (``ε k² ≈ 1e-11``); rows above take LAPACK's eigvalsh.
RCN_KMAX = math.sqrt(ACCURACY / EPS)
#: The rank certificate's coefficient: a batch has no arm whose Jacobian is known to be bounded.
RANK_COEF = RANK_RTOL**2


@_njit
def single_rows(Js, xdots, out, status, ws, jvja, L, z) -> None:  # pragma: no cover - numba
    """``status[b]`` = :func:`.single_kernel.packed_step_kernel` of row b into ``out[b]``.

    Status 4 where the kernel's rates may differ from the NumPy code's by more than
    :data:`ACCURACY` (:func:`_accurate`); ``L`` (m, m) and ``z`` (m,) scratch.
    """
    m = Js.shape[1]
    Y = ws[3 : 3 + m]
    for b in range(Js.shape[0]):
        st = packed_step_kernel(Js[b], xdots[b], out[b], ws, jvja)
        if st == 0 and not _accurate(Js[b], Y, ws[1], jvja, L, z):
            st = 4
        status[b] = st


@_njit
def _accurate(J, Y, lock, jvja, L, z) -> bool:  # pragma: no cover - numba
    """``ε · trace(G⁻¹) ‖J‖_F² / min_i N_ii ≤ ACCURACY`` (``κ(G) ≤ trace(G⁻¹) ‖J‖_F²``).

    The error of the Cholesky route grows with ``κ(G)`` and, for JVJA, with 1 / the smallest
    pivot; measured on the Panda (pose, position) and the UR5, it stayed below 17x this estimate.
    ``Y = L⁻¹J`` is the kernel's (``N_ii = 1 − ‖Y_i‖²``), ``lock`` is 0 on lockable columns.
    """
    m, n = J.shape
    if not gram_factor(J, L):
        return False
    tr = trace_inverse(L, z, m)
    nf = 0.0
    for i in range(m):
        for k in range(n):
            nf += J[i, k] * J[i, k]
    piv = 1.0
    if jvja:
        for i in range(n):
            if lock[i] == 0.0:
                d = 1.0
                for r in range(m):
                    d -= Y[r, i] * Y[r, i]
                piv = min(piv, d)
    return EPS * tr * nf <= ACCURACY * piv


# Eq. (15)
@_njit
def rcn_rows(Js, cols, out, status, G, W, scratch, kmax) -> None:  # pragma: no cover - numba
    """``k_S`` of every row and single-joint scenario into ``out`` (B, f), a status per row.

    The compiled sample's spectra (:func:`.sample_linalg._spectra`: one eigenbasis of ``G`` and
    a secular equation per scenario, :mod:`.rank_one_eigen`). Status 1 where a ``k_S`` is not
    finite or above ``kmax``: the eigenvalues of the two routes agree to a few ``ε ‖G‖``, so
    ``k_S`` to about ``ε k_S²``; such rows are left to the caller.
    """
    m = Js.shape[1]
    for b in range(Js.shape[0]):
        J = Js[b]
        for i in range(m):
            for j in range(i + 1):
                t = 0.0
                for k in range(J.shape[1]):
                    t += J[i, k] * J[j, k]
                G[i, j] = t
                G[j, i] = t
        _spectra(G, J, cols, out[b], W, RCN_MAX, scratch)
        st = 0
        for s in range(cols.shape[0]):
            if not out[b, s] <= kmax:
                st = 1
        status[b] = st


def reduced_condition_numbers(Js: np.ndarray, sc: Scenarios) -> tuple[np.ndarray, np.ndarray]:
    """``k_S`` (B, f) of single-joint scenarios ``sc`` and a status per row (≠ 0: not computed)."""
    Js = np.ascontiguousarray(Js, dtype=float)
    B, m, _ = Js.shape
    out = np.empty((B, sc.f))
    status = np.empty(B, dtype=np.int64)
    G, W, scratch = np.empty((m, m)), np.empty((m, m)), np.empty(m * m + 5 * m)
    cols = np.ascontiguousarray(sc.columns, dtype=np.int64)
    rcn_rows(Js, cols, out, status, G, W, scratch, RCN_KMAX)
    return out, status


def _unit_weights(sc: Scenarios) -> np.ndarray:
    """The weights over the largest: eq. (5) does not change, and their sum cannot overflow."""
    return sc.weights / sc.weights.max()


def single_workspace(sc: Scenarios | None, m: int, n: int) -> np.ndarray:
    """The workspace of :func:`single_rows` (:func:`.single_kernel.workspace`'s layout).

    As :class:`~fault_tolerance.control.controller.Controller` fills it: ``fw[0]`` 0 on lockable columns
    and +inf elsewhere, ``fw[1]`` the weights ``w_i/W`` (1 with uniform weights, ``alpha = -1/f``).
    ``sc=None``: LNVA (no scenario).
    """
    ws = np.zeros(workspace_shape.py_func(m, n))
    params, fw, _, _, _ = _views.py_func(ws, m, n)
    alpha = -1.0
    fw[1, :n] = 1.0
    if sc is not None:
        w = _unit_weights(sc)
        cols = sc.columns
        fw[0, :n] = np.inf
        fw[0, cols] = 0.0
        if np.all(sc.weights == sc.weights[0]):
            alpha = -1.0 / sc.f
        else:
            fw[1, :n] = 0.0
            fw[1, cols] = w / w.sum()
    params[:] = TRACE_MAX, THRESHOLD, RANK_COEF, alpha
    return ws


def rates(Js: np.ndarray, xdots: np.ndarray, sc: Scenarios | None) -> tuple[np.ndarray, np.ndarray]:
    """LNVA (``sc=None``) or least-norm JVJA rates of every row and the kernel's status per row.

    ``Js`` (B, m, n) and ``xdots`` (B, m) finite float arrays. Rows with status ≠ 0 hold no
    rates: the caller computes them otherwise.
    """
    Js = np.ascontiguousarray(Js, dtype=float)
    xdots = np.ascontiguousarray(xdots, dtype=float)
    B, m, n = Js.shape
    out = np.empty((B, n))
    status = np.empty(B, dtype=np.int64)
    ws = single_workspace(sc, m, n)
    single_rows(Js, xdots, out, status, ws, 0 if sc is None else 1, np.empty((m, m)), np.empty(m))
    return out, status
