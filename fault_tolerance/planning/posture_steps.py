"""The steps of the initial-posture search (Sec. III.D (i)), twice: plain and lean, same numbers.

Every step of :mod:`.posture` (the inverse kinematics, the Newton corrector ``q ← q + J⁺ e`` and
the null vector of the self-motion walk) asks for four things: the task error ``e(q)``, the task
Jacobian ``J(q)``, the Newton step ``J⁺ e`` and the null-space projector ``N``.

* :class:`ReferenceSteps` asks the arm (:meth:`~.arm.Arm.task_error`, :meth:`~.arm.Arm.jacobian`,
  with their input checks) and :func:`.linalg.projection` (``J⁺`` and ``N`` both, every time): the
  plain code the tests compare against.
* :class:`FastSteps` does the same floating-point operations, in the same order, without what the
  step does not use: no input checks, one Pinocchio call for the error and the Jacobian at the same
  ``q`` (``computeFrameJacobian`` also places the tip frame), only ``J⁺`` for a Newton step and only
  ``N`` for the walk, the desired rotation ``exp3`` taken once. Its numbers are the reference's bit
  for bit (the tests check it), damping near singularities included (the same
  :func:`.linalg.damping_factor`).

Why not a compiled least-norm solve: the golden-section refinement of the best curve point
compares values of ``K`` that differ by less than their rounding at its last steps, so the chosen
start moves by ~1e-8 rad when any step rounds differently (a Cholesky-based ``J⁺ e`` moved the
start of Figs. 6-7 by 1e-8 rad and 42 numbers of ``reproduce``'s summary by 1e-9 to 1e-7 relative).
The same numbers, only cheaper, keep ``reproduce`` as it was.

Example:
    >>> import numpy as np
    >>> from fault_tolerance import load_arm
    >>> arm = load_arm("planar_3r")
    >>> x0, q = np.array([0.35, 0.0]), np.array([0.5, 1.5, 1.0])
    >>> fast, ref = FastSteps(arm, x0), ReferenceSteps(arm, x0)
    >>> bool(np.array_equal(fast.error(q), ref.error(q)))
    True
    >>> J = fast.jacobian(q)
    >>> bool(np.array_equal(fast.newton(J, fast.error(q)), ref.newton(J, ref.error(q))))
    True
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from fault_tolerance.numerics.linalg import RANK_RTOL, damping_factor, projection
from fault_tolerance.resolution.indices import condition_numbers, reduced_singular_values

try:  # the gufunc behind np.linalg.eigh (same LAPACK call, same numbers, without the wrapper)
    from numpy.linalg import _umath_linalg

    def eigh(G):
        """``np.linalg.eigh(G)`` of a float64 matrix (or stack), without the wrapper."""
        return _umath_linalg.eigh_lo(G, signature="d->dd")

    eigh(np.eye(2))
except Exception:  # pragma: no cover - another NumPy layout
    eigh = np.linalg.eigh


def pinv_and_null(J: np.ndarray, eye: np.ndarray, null: bool = True):
    """``(J⁺, N or None)`` of one Jacobian: :func:`.linalg.projection`'s operations, bit for bit.

    One eigendecomposition for both, without the wrapper's overhead; ``eye`` is ``I`` (n x n).
    """
    lam, V = eigh(J @ J.T)
    lam = np.maximum(lam, 0.0)
    mu2 = damping_factor(math.sqrt(lam[0]))
    Jpinv = J.T @ (V / (lam + mu2 + (lam + mu2 == 0.0))) @ V.T
    if not null:
        return Jpinv, None
    keep = lam > (RANK_RTOL**2) * max(lam[-1], 1e-300)
    U = (J.T @ V[:, keep]) / np.sqrt(lam[keep])
    return Jpinv, eye - U @ U.T


def square_sum(J: np.ndarray, sc) -> float:
    """``K = Σ_S k_S²`` of ``J`` (eq. 15): the reference for :meth:`FastSteps.square_sums`."""
    k = condition_numbers(reduced_singular_values(J, sc))
    return float(k @ k)


_LWA = pin.LOCAL_WORLD_ALIGNED


def norm(x: np.ndarray) -> float:
    """``‖x‖`` of a vector as :func:`numpy.linalg.norm` computes it (``sqrt(x·x)``), cheaper.

    A strided view is copied first, as there: BLAS sums a strided dot product in another order.
    """
    x = x.ravel(order="K")
    return math.sqrt(x.dot(x))


class ReferenceSteps:
    """The plain steps: the arm's checked methods and :func:`.linalg.projection`.

    Args:
        arm: The arm.
        x_des: The task point the error is measured from, shape (m,).
    """

    def __init__(self, arm, x_des: np.ndarray) -> None:
        self.arm, self.x_des = arm, x_des

    def error(self, q: np.ndarray) -> np.ndarray:
        """Task error ``x_des − x(q)``, shape (m,)."""
        return self.arm.task_error(self.x_des, q)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Task Jacobian ``J(q)``, shape (m, n)."""
        return self.arm.jacobian(q)

    def newton(self, J: np.ndarray, err: np.ndarray) -> np.ndarray:
        """The Newton step ``J⁺ e`` (damped near singularities), shape (n,)."""
        return projection(J).Jpinv @ err

    def null_projector(self, J: np.ndarray) -> np.ndarray:
        """``N = I − J⁺J`` on the numerical null space, shape (n, n)."""
        return projection(J).N

    def square_sums(self, jacs, sc) -> np.ndarray:
        """``K`` of each Jacobian of ``jacs``, shape (L,)."""
        return np.array([square_sum(J, sc) for J in jacs])


class FastSteps:
    """The reference's steps without checks and unused parts; the same numbers, bit for bit.

    ``q`` must be a float array of shape (n,) (the search makes every one). :meth:`error` keeps the
    Jacobian of the same Pinocchio call: :meth:`jacobian` of that very array returns it.

    Args:
        arm: The arm.
        x_des: The task point the error is measured from, shape (m,).
    """

    def __init__(self, arm, x_des: np.ndarray) -> None:
        self.model, self.data, self.fid = arm.model, arm.model.createData(), arm.frame_id
        self.n, self.rows = arm.n, arm.rows
        self.x_des = np.asarray(x_des, dtype=float)
        full = np.zeros(6)
        full[arm.rows] = self.x_des
        self.full = full
        ang = [r for r in arm.rows if r >= 3]
        self.position_only = not ang
        self.all_angles = len(ang) == 3
        self.R_des = pin.exp3(full[3:]) if self.all_angles else None
        self.eye = np.eye(self.n)
        self._q: np.ndarray | None = None  # the q of the last error(), and J there
        self._J = np.empty((0, self.n))

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """``J(q)`` (that of the last :meth:`error` when ``q`` is the same array)."""
        if q is self._q:
            return self._J
        J6 = pin.computeFrameJacobian(self.model, self.data, q, self.fid, _LWA)
        return J6.reshape(6, self.n)[self.rows]

    def error(self, q: np.ndarray) -> np.ndarray:
        """``x_des − x(q)`` as :meth:`.Arm.task_error`; ``J(q)`` kept for :meth:`jacobian`."""
        J6 = pin.computeFrameJacobian(self.model, self.data, q, self.fid, _LWA)
        self._q, self._J = q, J6.reshape(6, self.n)[self.rows]
        M = self.data.oMf[self.fid]
        if self.position_only:
            return self.x_des - M.translation[self.rows]
        err = np.zeros(6)
        err[:3] = self.full[:3] - M.translation
        if self.all_angles:
            err[3:] = pin.log3(self.R_des @ M.rotation.T)
        else:
            err[3:] = self.full[3:] - pin.log3(M.rotation)
        return err[self.rows]

    def newton(self, J: np.ndarray, err: np.ndarray) -> np.ndarray:
        """``J⁺ e``, ``J⁺`` as :func:`.linalg.projection` forms it (damped the same way)."""
        return pinv_and_null(J, self.eye, False)[0] @ err

    def null_projector(self, J: np.ndarray) -> np.ndarray:
        """``N`` as :func:`.linalg.projection` forms it (rank-deficient directions dropped)."""
        lam, V = eigh(J @ J.T)
        lam = np.maximum(lam, 0.0)
        keep = lam > (RANK_RTOL**2) * max(lam[-1], 1e-300)
        U = (J.T @ V[:, keep]) / np.sqrt(lam[keep])
        return self.eye - U @ U.T

    def square_sums(self, jacs, sc) -> np.ndarray:
        """``K`` of each Jacobian, as :func:`square_sum`: one batched ``eigvalsh`` for them all.

        Each ``J Jᵀ`` is formed alone (as there); the reduced Gram matrices of one-joint scenarios
        are elementwise, and the batched ``eigvalsh`` calls LAPACK on each matrix as the
        unbatched one does, so the numbers are the same. Multi-joint scenarios: one by one.
        """
        if not sc.singletons or not len(jacs):
            return np.array([square_sum(J, sc) for J in jacs])
        G = np.array([J @ J.T for J in jacs])  # (L, m, m)
        cols = np.array(jacs)[:, :, sc.columns].transpose(0, 2, 1)  # (L, f, m)
        stack = G[:, None, :, :] - cols[:, :, :, None] * cols[:, :, None, :]
        k = condition_numbers(np.sqrt(np.maximum(np.linalg.eigvalsh(stack), 0.0)))  # (L, f)
        # each row copied: a fresh array is aligned as the reference's k is, and BLAS sums a
        # dot product of a misaligned row in another order
        return np.array([float(r @ r) for r in (row.copy() for row in k)])
