"""small_eigen: eigenvalues of small symmetric matrices as np.linalg.eigvalsh's, or a clear failure."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.numerics.fast import sample_dense as sl
from fault_tolerance.numerics.fast import small_eigen as se
from fault_tolerance.resolution.indices import RCN_MAX


def _eigenvalues(A, fn=se.symmetric_eigenvalues):
    """Sorted eigenvalues of ``A`` by ``fn`` (on a copy), or None when it reports failure."""
    m = A.shape[0]
    work = np.full(3 * m, np.nan)
    if not fn(np.array(A, dtype=float), m, work):
        return None
    return np.sort(work[:m])


def _agrees(A, tol=20.0):
    """The eigenvalues of ``A`` equal LAPACK's within ``tol m ε ‖A‖``."""
    ref = np.linalg.eigvalsh(A)
    got = _eigenvalues(A)
    assert got is not None
    scale = max(np.abs(ref).max(), np.finfo(float).tiny)
    np.testing.assert_allclose(got, ref, rtol=0, atol=tol * A.shape[0] * 2.2e-16 * scale)


def _gram(rng, m, n, spread=0.0):
    """``J Jᵀ`` of a random ``m x n`` J whose columns are scaled by 10^U(-spread, spread)."""
    J = rng.standard_normal((m, n)) * 10.0 ** rng.uniform(-spread, spread, size=(1, n))
    return J @ J.T


@pytest.mark.parametrize("m", [1, 2, 3, 4, 5, 6, 7, 12])
def test_random_symmetric_and_gram_matrices_agree(m):
    """Random symmetric (indefinite) and Gram matrices: LAPACK's eigenvalues to a few ε ‖A‖."""
    rng = np.random.default_rng(m)
    for _ in range(200):
        S = rng.standard_normal((m, m))
        _agrees(S + S.T)
        _agrees(_gram(rng, m, m + 1))


@pytest.mark.parametrize("m", [2, 3, 6, 12])
def test_rank_deficient_and_badly_scaled_agree(m):
    """Rank-deficient Gram matrices and columns scaled over 1e-8..1e8 (``k`` up to 1e16)."""
    rng = np.random.default_rng(10 + m)
    for r in range(1, m + 1):
        for spread in (0.0, 4.0, 8.0):
            _agrees(_gram(rng, m, r, spread))  # rank r
    for _ in range(100):
        A = _gram(rng, m, m + 1, 8.0)
        _agrees(A)
        D = np.diag(10.0 ** rng.uniform(-8, 8, size=m))
        _agrees(D @ A @ D / np.abs(D @ A @ D).max())


@pytest.mark.parametrize("m", [2, 3, 6, 12])
def test_clustered_and_repeated_eigenvalues_agree(m):
    """Repeated, nearly repeated (1e-12 apart) and exactly zero eigenvalues in a random basis."""
    rng = np.random.default_rng(20 + m)
    for lam in (
        np.ones(m),
        np.r_[np.ones(m - 1), 2.0],
        1.0 + 1e-12 * rng.standard_normal(m),
        np.r_[np.zeros(m // 2), np.ones(m - m // 2)],
        np.r_[np.zeros(m - 1), 1e8],
        np.r_[-1.0, np.ones(m - 1)],
    ):
        Q, _ = np.linalg.qr(rng.standard_normal((m, m)))
        _agrees((Q * lam) @ Q.T)


@pytest.mark.parametrize("m", [1, 2, 3, 6, 12])
def test_diagonal_zero_and_tridiagonal_matrices_are_exact(m):
    """A diagonal matrix gives its diagonal exactly, the zero matrix zeros; tridiagonal agrees."""
    rng = np.random.default_rng(30 + m)
    d = rng.standard_normal(m) * 10.0 ** rng.uniform(-8, 8, size=m)
    np.testing.assert_array_equal(_eigenvalues(np.diag(d)), np.sort(d))
    np.testing.assert_array_equal(_eigenvalues(np.zeros((m, m))), np.zeros(m))
    T = np.diag(d) + np.diag(rng.standard_normal(m - 1), 1) + np.diag(np.zeros(m - 1), -1)
    _agrees(T + np.triu(T, 1).T)
    A = _gram(rng, m, m)
    A[0, :] = A[:, 0] = 0.0  # an exact zero row and column
    _agrees(A)


def test_only_the_lower_triangle_is_read():
    """NaN above the diagonal changes nothing: the lower triangle is the matrix (LAPACK 'L')."""
    rng = np.random.default_rng(40)
    A = _gram(rng, 6, 7)
    B = A.copy()
    B[np.triu_indices(6, 1)] = np.nan
    np.testing.assert_array_equal(_eigenvalues(B), _eigenvalues(A))


def test_pair_eigenvalues_is_lapack_dlae2():
    """The 2 x 2 closed form: larger magnitude first; the smaller from the determinant."""
    rng = np.random.default_rng(41)
    for a, b, c in rng.standard_normal((500, 3)) * 10.0 ** rng.uniform(-8, 8, size=(500, 3)):
        r1, r2 = se.pair_eigenvalues(a, b, c)
        ref = np.linalg.eigvalsh(np.array([[a, b], [b, c]]))
        assert abs(r1) >= abs(r2)
        np.testing.assert_allclose(sorted([r1, r2]), ref, rtol=0, atol=4e-16 * np.abs(ref).max())
    assert se.pair_eigenvalues(1.0, 0.0, -1.0) == (1.0, -1.0)


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e160, 1e-130])
def test_not_finite_or_out_of_range_reports_failure(bad):
    """NaN, inf, or a matrix whose squares would over- or underflow: False (the caller uses LAPACK)."""
    A = _gram(np.random.default_rng(42), 6, 7)
    if bad in (1e160, 1e-130):
        A = A * bad
    else:
        A[3, 1] = bad
    assert _eigenvalues(A) is None
    lo, hi, ok = se.extreme_eigenvalues(A.copy(), 6, np.empty(18))
    assert not ok


def test_no_convergence_reports_failure():
    """A QL budget of 0 sweeps on an unreduced block fails instead of returning wrong numbers."""
    d, e2 = np.array([1.0, 2.0, 3.0]), np.array([1.0, 1.0, 0.0])
    assert se._block_eigenvalues(d, e2, 0, 2, 0) == -1


def test_plain_python_gives_the_same_numbers():
    """Without numba (``py_func``) the same eigenvalues, to rounding."""
    A = _gram(np.random.default_rng(43), 6, 7)
    work = np.empty(18)
    assert se.symmetric_eigenvalues.py_func(A.copy(), 6, work)
    np.testing.assert_allclose(np.sort(work[:6]), _eigenvalues(A), rtol=1e-13)


def _condition(J, cols):
    """``k_S`` and ``K`` with one eigenproblem per scenario (the kernel's fallback path)."""
    m = J.shape[0]
    G, W, t = J @ J.T, np.empty((m, m)), np.empty(3 * m)
    ks = np.array([sl._capped_k(*sl._reduced_extremes(G, J, i, W, t), RCN_MAX) for i in cols])
    return ks, float(ks @ ks)


def test_condition_numbers_as_the_reference_and_through_the_fallback():
    """``k_S`` by small_eigen per scenario equal ``ft.rcn``; a Jacobian scaled by 1e80 (small_eigen
    refuses it, LAPACK scales it) gives the same ``k_S`` through the fallback."""
    arm = ft.load_arm("panda", task="pose")
    q = np.array([0.1, -0.4, 0.2, -2.0, 0.1, 1.8, 0.6])
    J = arm.jacobian(q)
    cols = list(range(arm.n))
    ks, K = _condition(J, cols)
    np.testing.assert_allclose(ks, ft.rcn(J, cols), rtol=1e-10)
    assert K == pytest.approx(float(np.sum(ks**2)), rel=1e-14)
    G = (J * 1e80) @ (J * 1e80).T
    assert _eigenvalues(G - np.outer(J[:, 0], J[:, 0]) * 1e160) is None
    big, _ = _condition(J * 1e80, cols)
    np.testing.assert_allclose(big, ks, rtol=1e-10)
    W = np.empty((6, 6))
    assert sl._sigma_min(G, W, np.empty(18)) == pytest.approx(
        np.sqrt(np.linalg.eigvalsh(G)[0]), rel=1e-10
    )
