"""Batched analysis: the scalar API (``ft.resolve``, ``ft.jvj``, ``ft.rcn``) over B configurations.

Every function takes stacks of Jacobians ``Js`` (B, m, n) and works in chunks of at most
:data:`CHUNK` rows, so the temporaries stay bounded for any B (the output is allocated once).
The linear algebra is the scalar one (:mod:`.linalg`: one eigendecomposition of ``J Jᵀ`` per
row, damped near singularities; (G1)/(G2) for the reduced rates), done by NumPy's stacked
``eigh``/``solve``, so the results equal the scalar API's to rounding: measured at most 1.05e-11
relative on random and ill-conditioned rows of the shipped arms and the Panda, tested at
``BATCH_RTOL = 1e-10`` (docs/batch.md, :mod:`.batch_agreement`).

Example:
    >>> import numpy as np, fault_tolerance as ft
    >>> from fault_tolerance import batch
    >>> arm = ft.load_arm("planar_3r")
    >>> Q = np.random.default_rng(0).uniform(-2, 2, (100, 3))
    >>> Js = batch.jacobians(arm, Q)                      # (100, 2, 3), Pinocchio per row
    >>> xd = np.tile([0.1, 0.0], (100, 1))
    >>> qd = batch.resolve("jvja", Js, xd, lockable=[1, 2], intolerable="nan")
    >>> lam = batch.jvj(Js, xd, qd, lockable=[1, 2], intolerable="nan")
    >>> k = batch.rcn(Js, lockable=[1, 2])                # (100, 2)
    >>> bool(np.allclose(np.einsum("bmn,bn->bm", Js, qd)[np.isfinite(lam)], xd[np.isfinite(lam)]))
    True
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fault_tolerance.errors import IntolerableFailure, InvalidInput
from fault_tolerance.numerics.checks import finite
from fault_tolerance.numerics.linalg import PIVOT_TOL, projection, reduced_rates
from fault_tolerance.resolution.indices import (
    RESPONSES,
    condition_numbers,
    reduced_singular_values,
)
from fault_tolerance.resolution.jvja import jvja_rates
from fault_tolerance.resolution.registry import KERNEL_JVJA, KERNEL_LNVA, get, names
from fault_tolerance.resolution.scenarios import Scenarios, scenarios

#: Rows per chunk: temporaries are O(CHUNK · n²) floats, whatever B is.
CHUNK = 4096
#: What to do where a scenario is intolerable (N[S, S] singular): raise like the scalar API, or
#: put NaN in that row of the output.
INTOLERABLE = ("raise", "nan")


def jacobians(arm, Q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Task Jacobians of ``arm`` at the rows of ``Q`` (B, n) from Pinocchio, shape (B, m, n).

    One output array is allocated (or ``out`` is filled); Pinocchio computes each row.
    """
    Q = np.ascontiguousarray(Q, dtype=float)
    if Q.ndim != 2 or Q.shape[1] != arm.n:
        raise InvalidInput(f"Q must have shape (B, {arm.n}) for {arm.name}, got {Q.shape}")
    if not np.all(np.isfinite(Q)):
        raise InvalidInput("Q must be finite")
    B = Q.shape[0]
    if out is None:
        out = np.empty((B, arm.m, arm.n))
    elif out.shape != (B, arm.m, arm.n):
        raise InvalidInput(f"out must have shape {(B, arm.m, arm.n)}, got {out.shape}")
    for b in range(B):
        out[b] = arm.jacobian_unchecked(Q[b])
    return out


def _check(Js, *vectors) -> tuple[np.ndarray, ...]:
    Js = np.asarray(Js, dtype=float)
    if Js.ndim != 3:
        raise InvalidInput(f"Js must have shape (B, m, n), got {Js.shape}")
    B, m, n = Js.shape
    outs = [Js]
    for name, v, size in vectors:
        v = np.asarray(v, dtype=float)
        if v.shape != (B, size):
            raise InvalidInput(f"{name} must have shape ({B}, {size}), got {v.shape}")
        outs.append(v)
    finite(Js, "Js")
    for (name, _, _), v in zip(vectors, outs[1:], strict=True):
        finite(v, name)
    return tuple(outs)


def _scenarios(Js: np.ndarray, lockable, weights, joint_names) -> Scenarios:
    _, m, n = Js.shape
    return scenarios(lockable, n, r=n - m, weights=weights, joint_names=joint_names)


#: The kernel modes this module batches by stacked NumPy (and the compiled step): LNVA, JVJA.
BATCHED = (KERNEL_LNVA, KERNEL_JVJA)


def _option(intolerable: str) -> str:
    if intolerable not in INTOLERABLE:
        raise InvalidInput(f"intolerable={intolerable!r} is not one of {INTOLERABLE}")
    return intolerable


def _tolerable(N: np.ndarray, sc: Scenarios, intolerable: str) -> np.ndarray:
    """Rows whose every scenario is tolerable; raise on the first bad one when asked to."""
    piv = sc.pivots(N)
    good = np.all(piv >= PIVOT_TOL, axis=1)
    if intolerable == "raise" and not good.all():
        b = int(np.argmin(good))
        k = int(np.argmin(piv[b]))
        raise IntolerableFailure(sc.name(sc.sets[k]), float(piv[b, k]))
    return good


def _reduced(base: np.ndarray, N: np.ndarray, S: list[int], good: np.ndarray) -> np.ndarray:
    """(G1) per row: :func:`~fault_tolerance.numerics.linalg.reduced_rates` on the stack.

    Rows not ``good`` (an intolerable scenario) get ``N = I``: finite numbers the caller drops.
    """
    return reduced_rates(base, np.where(good[:, None, None], N, np.eye(N.shape[-1])), S)


def _jvja_rows(a, N, sc: Scenarios, good, response: str) -> np.ndarray:
    """JVJA (5) of every row: :func:`~fault_tolerance.resolution.jvja.jvja_rates` on the stack.

    Rows not ``good`` (an intolerable scenario) get ``N = I``: finite numbers the caller drops.
    """
    N = np.where(good[:, None, None], N, np.eye(N.shape[-1]))
    return jvja_rates(a, N, sc, sc.pivots(N), response)


def resolve(
    name: str,
    Js: np.ndarray,
    xdots: np.ndarray,
    lockable=None,
    *,
    weights: Sequence[float] | None = None,
    response: str = "least_norm",
    joint_names: Sequence[str] = (),
    intolerable: str = "raise",
    chunk: int = CHUNK,
    options: dict | None = None,
) -> np.ndarray:
    """Rates of the registered resolver ``name`` for every row, shape (B, n).

    Row b equals ``ft.resolve(name, Js[b], xdots[b], lockable, ...)``. ``intolerable="nan"``
    fills rows with an intolerable scenario with NaN instead of raising. LNVA and JVJA are
    batched (below); another registered resolver runs its reference rates row by row, with its
    ``options`` (``weights`` and ``response`` fill options of those names). A resolver that needs
    the configuration (MDA: the Jacobian derivatives at each row's ``q``) is refused: use
    :func:`ft.resolve` per row.

    LNVA and JVJA run :func:`resolve_stacked`, the stacked NumPy code (49× a loop of
    ``ft.resolve`` over 300 Panda configurations; a compiled row kernel was 1.7× faster still and
    did not earn its compile time).
    """
    entry = get(name)
    if entry.compiled not in BATCHED or options:
        run = {"weights": weights, "response": response}
        return _per_row(
            entry, Js, xdots, lockable, entry.options_with(options, run), joint_names, intolerable
        )
    Js, xdots, sc = _resolve_input(
        name, Js, xdots, lockable, weights, response, intolerable, joint_names
    )
    return _stacked(Js, xdots, sc, response, intolerable, chunk)


def _per_row(entry, Js, xdots, lockable, options, joint_names, intolerable) -> np.ndarray:
    """Rates of a resolver the batch does not know, by its reference rates row by row."""
    if entry.needs_configuration:
        raise InvalidInput(
            f"batched resolver '{entry.name}' needs the configuration of every row (arm and q); "
            f"batched resolvers are {[n for n in names() if not get(n).needs_configuration]}; "
            "call ft.resolve per row"
        )
    _option(intolerable)
    Js, xdots = _check(Js, ("xdots", xdots, np.shape(Js)[1]))
    out = np.empty((Js.shape[0], Js.shape[2]))
    for b in range(Js.shape[0]):
        try:
            out[b] = entry.call(Js[b], xdots[b], lockable, joint_names=joint_names, **options)
        except IntolerableFailure:
            if intolerable == "raise":
                raise
            out[b] = np.nan
    return out


def resolve_stacked(
    name: str,
    Js: np.ndarray,
    xdots: np.ndarray,
    lockable=None,
    *,
    weights: Sequence[float] | None = None,
    response: str = "least_norm",
    joint_names: Sequence[str] = (),
    intolerable: str = "raise",
    chunk: int = CHUNK,
) -> np.ndarray:
    """:func:`resolve` by stacked NumPy alone (the path without numba, and its reference)."""
    Js, xdots, sc = _resolve_input(
        name, Js, xdots, lockable, weights, response, intolerable, joint_names
    )
    return _stacked(Js, xdots, sc, response, intolerable, chunk)


def _resolve_input(name, Js, xdots, lockable, weights, response, intolerable, joint_names):
    """Validated ``Js``, ``xdots`` and the scenarios (None for LNVA) of :func:`resolve`."""
    mode = get(name).compiled
    if mode not in BATCHED:
        raise InvalidInput(f"stacked resolver '{name}' is not one of {_stacked_names()}")
    if response not in RESPONSES:
        raise InvalidInput(f"response {response!r} is not one of {RESPONSES}")
    _option(intolerable)
    Js, xdots = _check(Js, ("xdots", xdots, np.shape(Js)[1]))
    sc = _scenarios(Js, lockable, weights, joint_names) if mode == KERNEL_JVJA else None
    return Js, xdots, sc


def _stacked_names() -> list[str]:
    return [n for n in names() if get(n).compiled in BATCHED]


def _stacked(Js, xdots, sc: Scenarios | None, response, intolerable, chunk) -> np.ndarray:
    """LNVA (``sc=None``) or JVJA rates of every row by stacked NumPy, in chunks."""
    B, m, n = Js.shape
    out = np.empty((B, n))
    for s in range(0, B, max(int(chunk), 1)):
        e = min(s + max(int(chunk), 1), B)
        P = projection(Js[s:e])
        Jpinv, N = P.Jpinv, P.N
        a = np.einsum("bnm,bm->bn", Jpinv, xdots[s:e])
        if sc is None:
            out[s:e] = a
            continue
        good = _tolerable(N, sc, intolerable)
        out[s:e] = _jvja_rows(a, N, sc, good, response)
        out[s:e][~good] = np.nan
    return out


# Eqn. (9), (10)
def jvj(
    Js: np.ndarray,
    xdots: np.ndarray,
    qds: np.ndarray,
    lockable=None,
    *,
    weights: Sequence[float] | None = None,
    response: str = "least_norm",
    joint_names: Sequence[str] = (),
    intolerable: str = "raise",
    chunk: int = CHUNK,
) -> np.ndarray:
    """Square-sum joint velocity jump of rates ``qds`` for every row [(rad/s)²], shape (B,).

    Row b equals ``ft.jvj(Js[b], xdots[b], qds[b], lockable, ...)``; NaN where a scenario is
    intolerable and ``intolerable="nan"``.
    """
    if response not in RESPONSES:
        raise InvalidInput(f"response {response!r} is not one of {RESPONSES}")
    intolerable = _option(intolerable)
    m = np.shape(Js)[1] if np.ndim(Js) == 3 else 0
    n = np.shape(Js)[2] if np.ndim(Js) == 3 else 0
    Js, xdots, qds = _check(Js, ("xdots", xdots, m), ("qds", qds, n))
    sc = _scenarios(Js, lockable, weights, joint_names)
    B = Js.shape[0]
    out = np.empty(B)
    step = max(int(chunk), 1)
    for s in range(0, B, step):
        e = min(s + step, B)
        P = projection(Js[s:e])
        Jpinv, N = P.Jpinv, P.N
        good = _tolerable(N, sc, intolerable)
        qd = qds[s:e]
        base = np.einsum("bnm,bm->bn", Jpinv, xdots[s:e]) if response == "least_norm" else qd
        lam = np.zeros(e - s)
        for S, w in zip(sc.sets, sc.weights, strict=True):
            d = _reduced(base, N, list(S), good) - qd
            lam += w * np.einsum("bn,bn->b", d, d)
        lam[~good] = np.nan
        out[s:e] = lam
    return out


# Eqn. (15)
def rcn(
    Js: np.ndarray, lockable=None, *, joint_names: Sequence[str] = (), chunk: int = CHUNK
) -> np.ndarray:
    """Reduced condition numbers ``k_S`` of every row, shape (B, f), as :func:`ft.rcn`.

    ``J_S J_Sᵀ = J Jᵀ − J[:, S] J[:, S]ᵀ``: one stacked ``eigvalsh`` of (B, f, m, m) per chunk
    (:func:`rcn_stacked`).
    """
    (Js,) = _check(Js)
    sc = _scenarios(Js, lockable, None, joint_names)
    return _rcn_stacked(Js, sc, chunk)


def rcn_stacked(
    Js: np.ndarray, lockable=None, *, joint_names: Sequence[str] = (), chunk: int = CHUNK
) -> np.ndarray:
    """:func:`rcn` by stacked NumPy alone (the path without numba, and its reference)."""
    (Js,) = _check(Js)
    return _rcn_stacked(Js, _scenarios(Js, lockable, None, joint_names), chunk)


def _rcn_stacked(Js: np.ndarray, sc: Scenarios, chunk: int) -> np.ndarray:
    """(15) of every row by :func:`~fault_tolerance.resolution.indices.rcn`'s own functions."""
    B = Js.shape[0]
    out = np.empty((B, sc.f))
    step = max(int(chunk), 1)
    for s in range(0, B, step):
        e = min(s + step, B)
        out[s:e] = condition_numbers(reduced_singular_values(Js[s:e], sc))
    return out


def square_sum_rcn(Js: np.ndarray, lockable=None, **options) -> np.ndarray:
    """``K = Σ_S k_S²`` of every row, shape (B,)."""
    k = rcn(Js, lockable, **options)
    return np.einsum("bf,bf->b", k, k)


def mean_jump(
    Js: np.ndarray, lockable=None, *, weights=None, intolerable: str = "nan", chunk: int = CHUNK
) -> np.ndarray:
    r"""JVJA's square-sum jump averaged over unit task directions, shape (B,) [(rad/s)² per (unit)²].

    JVJA's rates and the reduced rates are linear in ``ẋ``, so :math:`\lambda(\dot x) = \dot x^T Q
    \dot x` and its mean over the unit sphere of Rᵐ is :math:`\mathrm{tr}(Q)/m = \frac1m\sum_k
    \lambda(e_k)` (exact, no direction sampling).
    """
    Js = np.asarray(Js, dtype=float)
    B, m, _ = Js.shape
    total = np.zeros(B)
    for k in range(m):
        e = np.zeros((B, m))
        e[:, k] = 1.0
        opts = dict(weights=weights, intolerable=intolerable, chunk=chunk)
        qd = resolve("jvja", Js, e, lockable, **opts)
        if intolerable == "nan":
            qd = np.where(np.isfinite(qd), qd, 0.0)
        lam = jvj(Js, e, qd, lockable, **opts)
        total += lam
    return total / m
