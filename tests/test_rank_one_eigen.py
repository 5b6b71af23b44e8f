"""rank_one_eigen: the eigenbasis of G and the extreme eigenvalues of G − v vᵀ, as np.linalg.eigvalsh."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.numerics.fast import rank_one_eigen as ro
from fault_tolerance.numerics.fast import sample_dense as sl
from fault_tolerance.resolution.indices import RCN_MAX

EPS = np.finfo(float).eps


def _basis(G):
    """``(ok, V, d)`` of :func:`ro.eigenpairs` on a copy of ``G``, the eigenvectors by columns."""
    m = G.shape[0]
    Vt, d = np.full((m, m), np.nan), np.full(m, np.nan)
    ok = ro.eigenpairs(np.array(G, dtype=float), m, Vt, d, np.empty(2 * m))
    return ok, Vt.T, d


def _extremes(G, v):
    """``(λ_min, λ_max)`` of ``G − v vᵀ`` through the eigenbasis of ``G`` and the secular roots."""
    m = G.shape[0]
    ok, V, d = _basis(G)
    assert ok
    lo, hi, ok = ro.downdate_extremes(V.T.copy(), d, v.reshape(m, 1), 0, m, np.empty(m))
    assert ok
    return lo, hi


def _agrees(G, v, tol=30.0):
    """The extremes of ``G − v vᵀ`` equal LAPACK's within ``tol m ε ‖G‖``."""
    ref = np.linalg.eigvalsh(G - np.outer(v, v))
    lo, hi = _extremes(G, v)
    atol = tol * G.shape[0] * EPS * max(np.abs(np.linalg.eigvalsh(G)).max(), 1e-300)
    np.testing.assert_allclose([lo, hi], [ref[0], ref[-1]], rtol=0, atol=atol)


def _jacobian(rng, m, n, spread=0.0):
    return rng.standard_normal((m, n)) * 10.0 ** rng.uniform(-spread, spread, size=(1, n))


@pytest.mark.parametrize("m", [1, 2, 3, 4, 6, 7, 12])
def test_eigenpairs_reconstruct_the_matrix(m):
    """``V`` orthogonal, ``V diag(d) Vᵀ = A``, ``d`` ascending and LAPACK's, for random and
    clustered symmetric matrices, a diagonal one and zero."""
    rng = np.random.default_rng(m)
    Q, _ = np.linalg.qr(rng.standard_normal((m, m)))
    mats = [np.zeros((m, m)), np.diag(rng.standard_normal(m)), (Q * np.ones(m)) @ Q.T]
    mats += [(Q * (1.0 + 1e-12 * rng.standard_normal(m))) @ Q.T]
    for _ in range(50):
        S = rng.standard_normal((m, m))
        J = _jacobian(rng, m, m + 1, 4.0)
        mats += [S + S.T, J @ J.T]
    for A in mats:
        ok, V, d = _basis(A)
        assert ok
        scale = max(np.abs(A).max(), 1e-300)
        assert np.all(np.diff(d) >= 0.0)
        np.testing.assert_allclose(V.T @ V, np.eye(m), atol=50 * m * EPS)
        np.testing.assert_allclose((V * d) @ V.T, A, atol=50 * m * EPS * scale)
        np.testing.assert_allclose(d, np.linalg.eigvalsh(A), atol=20 * m * EPS * scale)


@pytest.mark.parametrize("m", [1, 2, 3, 5, 6, 12])
def test_downdates_of_gram_matrices_agree(m):
    """``J Jᵀ − J_i J_iᵀ`` for random Jacobians, columns scaled over 1e-4..1e4 and 1e-8..1e8,
    and reduced Jacobians of rank below m (``W`` singular)."""
    rng = np.random.default_rng(10 + m)
    for spread in (0.0, 4.0, 8.0):
        for n in (m, m + 1, m + 3):
            for _ in range(30):
                J = _jacobian(rng, m, n, spread)
                for i in range(n):
                    _agrees(J @ J.T, J[:, i])


@pytest.mark.parametrize("m", [2, 3, 6, 12])
def test_repeated_eigenvalues_and_zero_components_agree(m):
    """``G`` with repeated (or 1e-12-close) eigenvalues; ``v`` along one eigenvector, in a
    subspace, zero, or a multiple of a column of a diagonal ``G``."""
    rng = np.random.default_rng(20 + m)
    Q, _ = np.linalg.qr(rng.standard_normal((m, m)))
    spectra = [np.ones(m), np.r_[np.ones(m - 1), 3.0], np.r_[0.5, np.ones(m - 1)]]
    spectra += [1.0 + 1e-12 * rng.standard_normal(m), np.sort(rng.uniform(0.1, 2.0, m))]
    for lam in spectra:
        G = (Q * lam) @ Q.T
        D = np.diag(lam)
        for v in (
            rng.standard_normal(m) * 0.5,
            Q[:, 0] * 0.7,
            Q[:, -1] * 0.9,
            Q[:, :2] @ rng.standard_normal(2) * 0.3,
            np.zeros(m),
            Q[:, 0] * np.sqrt(lam[0]),  # W singular: the whole first eigenvalue taken
        ):
            _agrees(G, v)
        e = np.zeros(m)
        e[m // 2] = 0.8
        _agrees(D, e)
        _agrees(D, rng.standard_normal(m) * 0.4)


def test_roots_report_failure_on_nan():
    """NaN in ``u`` or ``d``: no root claimed (the caller takes the QL path)."""
    d, u2 = np.array([1.0, 2.0, 3.0]), np.array([0.1, np.nan, 0.2])
    assert not ro.lowest_root(d, u2, 3, np.nansum(u2) + 1.0)[1]
    assert not ro.highest_root(d, np.array([0.1, 0.2, np.nan]), 3)[1]
    assert not ro.highest_root(np.array([1.0, np.nan, 3.0]), np.array([0.1, 0.2, 0.3]), 3)[1]


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e160, 1e-130])
def test_eigenpairs_refuse_non_finite_or_out_of_range(bad):
    """As small_eigen: NaN, inf or a matrix whose squares would over- or underflow is refused."""
    G = np.eye(4) + 0.1
    if bad in (1e160, 1e-130):
        G = G * bad
    else:
        G[2, 1] = G[1, 2] = bad
    assert not _basis(G)[0]


def _panda():
    arm = ft.load_arm("panda", task="pose")
    return arm.jacobian(np.array([0.1, -0.4, 0.2, -2.0, 0.1, 1.8, 0.6]))


def _close_k(a, b):
    """``k_S`` agree to 1e-12 plus their rounding, which grows like ε k² (tests/test_fastpath.py)."""
    b = np.asarray(b)
    np.testing.assert_array_less(np.abs(np.asarray(a) - b), (1e-12 + 1e-15 * b**2) * b)


def _spectra(J, fn=sl._spectra):
    m, n = J.shape
    ks = np.empty(n)
    W, scratch = np.empty((m, m)), np.empty(m * m + 5 * m)
    K, smin = fn(J @ J.T, J, np.arange(n), ks, W, RCN_MAX, scratch)
    return ks, K, smin


def test_sample_spectra_equal_the_reference_and_each_path():
    """The compiled sample's k_S, K, σ_min (eigenbasis + secular roots) equal ``ft.rcn`` and the
    per-scenario QL path; a 1e80-scaled Jacobian (eigenbasis refused) gives the same k_S through
    the fallback, and so does a secular root that fails (plain Python, roots refused)."""
    J = _panda()
    ks, K, smin = _spectra(J)
    _close_k(ks, ft.rcn(J, list(range(7))))
    assert K == pytest.approx(float(ks @ ks), rel=1e-14)
    assert smin == pytest.approx(np.linalg.svd(J, compute_uv=False)[-1], rel=1e-12)
    m = J.shape[0]
    G, W, t = J @ J.T, np.empty((m, m)), np.empty(3 * m)
    ql = [sl._capped_k(*sl._reduced_extremes(G, J, i, W, t), RCN_MAX) for i in range(7)]
    _close_k(ks, ql)
    assert not _basis((J * 1e80) @ (J * 1e80).T)[0]
    big, _, smin_big = _spectra(J * 1e80)
    _close_k(big, ks)
    assert smin_big == pytest.approx(smin * 1e80, rel=1e-10)


def test_a_failed_root_takes_the_ql_path(monkeypatch):
    """With every secular root refused, ``_spectra`` (plain Python) still gives the same k_S."""
    J = _panda()
    ks, K, smin = _spectra(J)
    monkeypatch.setattr(sl, "downdate_extremes", lambda *a: (np.nan, np.nan, False))
    slow, K2, smin2 = _spectra(J, sl._spectra.py_func)
    _close_k(slow, ks)
    assert (K2, smin2) == pytest.approx((K, smin), rel=1e-8)


def _side_by_side(d, Z):
    """``(λ_min, λ_max, ok)`` rows of :func:`ro.all_extremes` for every column of ``Z``."""
    m, f = Z.shape
    lam = np.full((3, f), np.nan)
    X = np.full((ro.LANE_ROWS + 1, max(f, m)), np.nan)
    ro.all_extremes(d, np.ascontiguousarray(Z), np.arange(f), m, np.empty((m, f)), X, lam)
    return lam


def _one_by_one(d, z):
    """The scalar roots of one scenario (``z`` in the eigenbasis)."""
    u2 = z * z
    lo, ok1 = ro.lowest_root(d, u2, len(d), u2.sum())
    hi, ok2 = ro.highest_root(d, u2, len(d))
    return lo, hi, ok1 and ok2


@pytest.mark.parametrize("m", [2, 3, 6, 12])
def test_side_by_side_roots_equal_the_scalar_roots(m):
    """``all_extremes`` (every scenario's steps side by side) gives the scalar functions' roots
    to rounding and LAPACK's within 30 m ε ‖G‖: random Jacobians with columns scaled over
    1e-8..1e8, fewer and more scenarios than m, repeated eigenvalues, and the lanes the scalar
    functions take alone (a zero weight at the nearest pole, ``v`` along one eigenvector, zero)."""
    rng = np.random.default_rng(40 + m)
    cases = []
    for spread in (0.0, 4.0, 8.0):
        for n in (1, m, m + 3):
            for _ in range(10):
                J = _jacobian(rng, m, n, spread)
                ok, V, d = _basis(J @ J.T)
                cases.append((d, V.T @ J, J @ J.T, J))
    Q, _ = np.linalg.qr(rng.standard_normal((m, m)))
    for lam in (np.ones(m), np.r_[np.ones(m - 1), 3.0], np.sort(rng.uniform(0.1, 2.0, m))):
        cols = [Q[:, 0] * 0.7, Q[:, -1] * 0.9, np.zeros(m), rng.standard_normal(m) * 0.4]
        cols += [Q[:, [0, -1]] @ [0.3, 0.4], Q[:, -2:] @ [0.2, 0.5]]  # u_2 = 0, u_{m-1} = 0
        G, J = (Q * lam) @ Q.T, np.array(cols).T
        ok, V, d = _basis(G)
        cases.append((d, V.T @ J, G, J))
    for d, Z, G, J in cases:
        lam = _side_by_side(d, Z)
        scale = max(d[-1], 1e-300)
        for s in range(Z.shape[1]):
            lo, hi, ok = _one_by_one(d, Z[:, s])
            assert lam[2, s] == 1.0 and ok
            np.testing.assert_allclose(lam[:2, s], [lo, hi], rtol=0, atol=8 * EPS * scale)
            ref = np.linalg.eigvalsh(G - np.outer(J[:, s], J[:, s]))
            atol = 30 * m * EPS * scale
            np.testing.assert_allclose(lam[:2, s], [ref[0], ref[-1]], rtol=0, atol=atol)


def test_side_by_side_roots_report_nan():
    """A scenario with NaN weights is reported not solved; the others still are."""
    d = np.array([1.0, 2.0, 3.0])
    Z = np.array([[0.3, np.nan], [0.2, 0.1], [0.4, 0.2]])
    lam = _side_by_side(d, Z)
    assert lam[2].tolist() == [1.0, 0.0]
    np.testing.assert_allclose(lam[:2, 0], _one_by_one(d, Z[:, 0])[:2], rtol=0, atol=1e-15)
