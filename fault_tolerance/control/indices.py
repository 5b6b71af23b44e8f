"""The indices of a :class:`~fault_tolerance.control.controller.Controller`: RCN, its gradient, the kinematic Hessian.

Plain functions of a :class:`~fault_tolerance.control.workspace.ControllerWorkspace`: the reduced
condition numbers ``k_S`` of all scenarios (eq. 15) from one batched ``eigvalsh`` of the stack
``J_S J_Sᵀ``, the gradient of ``K = Σ_S k_S²`` (MDA's null-space step) from one batched ``eigh``,
and the kinematic Hessian ``∂J/∂q`` of the tip frame from its Jacobians (no finite differences).
They read the workspace's ``model``, ``data``, ``frame_id``, ``n``, ``m``, ``rows``, ``keep`` and
``upper`` and write its scratch ``Jm`` and ``stack``.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from fault_tolerance.control.workspace import ControllerWorkspace
from fault_tolerance.resolution.indices import RCN_MAX, RCN_SINGULAR

__all__ = [
    "djac",
    "jacobian",
    "jacobian_derivatives",
    "rcn",
    "rcn_gradient",
    "rcn_of",
    "reduced_gram",
]

_LWA = pin.LOCAL_WORLD_ALIGNED
_WORLD = pin.WORLD


def _hat_tensor() -> np.ndarray:
    """``hat(x).ravel() = x @ H`` with ``hat(x) y = x × y``, i.e. ``hat(x)[a, b] = -ε_abc x_c``."""
    eps = np.zeros((3, 3, 3))
    for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        eps[a, b, c], eps[a, c, b] = 1.0, -1.0
    return -np.transpose(eps, (2, 0, 1)).reshape(3, 9)


_HAT = _hat_tensor()


def _ad_tensor() -> np.ndarray:
    """``ad(V).ravel() = V @ T`` for a spatial velocity ``V = [v; ω]``: ``[[ω̂, v̂], [0, ω̂]]``."""
    T = np.zeros((6, 6, 6))
    H = _HAT.reshape(3, 3, 3)  # H[c, a, b] = -ε_abc
    T[3:, :3, :3] = H
    T[:3, :3, 3:] = H
    T[3:, 3:, 3:] = H
    return T.reshape(6, 36)


_AD = _ad_tensor()


def jacobian(ws: ControllerWorkspace, q: np.ndarray) -> np.ndarray:
    """Task Jacobian at ``q``, shape (m, n), computed as in the steps (no input validation)."""
    return pin.computeFrameJacobian(ws.model, ws.data, q, ws.frame_id, _LWA)[ws.rows]


def reduced_gram(ws: ControllerWorkspace, J: np.ndarray) -> np.ndarray:
    """The stack ``J_S J_Sᵀ`` of all scenarios, shape (f, m, m), in the workspace."""
    np.multiply(J, ws.keep, out=ws.Jm)
    np.matmul(ws.Jm, J.T, out=ws.stack)
    return ws.stack


def rcn(ws: ControllerWorkspace, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Reduced condition numbers ``k_S`` of all scenarios at ``q``, eq. (15), shape (f,).

    One batched ``eigvalsh`` of the stack ``J_S J_Sᵀ``; capped at ``RCN_MAX`` as
    :func:`fault_tolerance.rcn`.
    """
    return rcn_of(ws, jacobian(ws, q), out)


def rcn_of(ws: ControllerWorkspace, J: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """As :func:`rcn`, for a given task Jacobian ``J`` of shape (m, n)."""
    if out is None:
        out = np.empty(ws.f)
    sigma = np.linalg.eigvalsh(reduced_gram(ws, J))  # (f, m) ascending, σ²
    np.maximum(sigma, 0.0, out=sigma)
    np.sqrt(sigma, out=sigma)
    smax, smin = sigma[:, -1], sigma[:, 0]
    np.maximum(smin, smax / RCN_MAX, out=smin)
    if min(smin.tolist()) > 0.0:
        np.divide(smax, smin, out=out)
    else:  # some reduced Jacobian is zero: σ_max = 0
        out[...] = np.where(smax > 0, smax / np.where(smin > 0, smin, 1.0), RCN_MAX)
    np.minimum(out, RCN_MAX, out=out)
    return out


def jacobian_derivatives(ws: ControllerWorkspace, q: np.ndarray) -> np.ndarray:
    """``dJ[j] = ∂J/∂q_j``, shape (n, m, n), as :meth:`Arm.jacobian_derivatives`, vectorised."""
    model, data, fid = ws.model, ws.data, ws.frame_id
    pin.computeJointJacobians(model, data, q)
    Jw = pin.getFrameJacobian(model, data, fid, _WORLD)
    Jl = pin.getFrameJacobian(model, data, fid, _LWA)  # also updates data.oMf[fid]
    return djac(ws, Jw, Jl, data.oMf[fid].translation)


def djac(ws: ControllerWorkspace, Jw: np.ndarray, Jl: np.ndarray, p: np.ndarray) -> np.ndarray:
    r"""Kinematic Hessian of the tip frame from its WORLD and LOCAL_WORLD_ALIGNED Jacobians.

    WORLD columns move as :math:`\partial J_k/\partial q_j = \mathrm{ad}(J_j)\, J_k` (j < k);
    the linear rows of ``LOCAL_WORLD_ALIGNED`` add :math:`\partial\omega_k/\partial q_j
    \times p + \omega_k \times \partial p/\partial q_j`.
    """
    n = ws.n
    ad = np.dot(Jw.T, _AD).reshape(n, 6, 6)
    dJ = np.matmul(ad, Jw)  # (n, 6, n): ad(J_j) J_k
    dJ *= ws.upper  # zero unless joint j comes before joint k
    hat_p = np.dot(p, _HAT).reshape(3, 3)
    hat_dp = np.dot(Jl[:3].T, _HAT).reshape(n, 3, 3)  # ∂p/∂q_j: linear part of LWA column j
    dJ[:, :3, :] -= np.matmul(hat_p, dJ[:, 3:, :])  # + ∂ω_k/∂q_j × p
    dJ[:, :3, :] -= np.matmul(hat_dp, Jw[3:])  # + ω_k × ∂p/∂q_j
    return dJ[:, ws.rows, :]


def rcn_gradient(ws: ControllerWorkspace, J: np.ndarray, dJ: np.ndarray) -> np.ndarray:
    r"""Gradient of ``K = Σ_S k_S²``, shape (n,), as :func:`fault_tolerance.rcn_gradient`.

    One batched ``eigh`` of ``J_S J_Sᵀ`` gives σ² and the left singular vectors ``u``; the
    right ones are ``v = J_Sᵀu/σ``, and :math:`\partial\sigma/\partial q_j = u^T \partial_j
    J_S\, v`. A singular reduced robot (``σ_min <= σ_max / RCN_SINGULAR``) adds nothing, as in
    the reference (eq. S1).
    """
    n, m = ws.n, ws.m
    lam, U = np.linalg.eigh(reduced_gram(ws, J))
    s = np.sqrt(np.maximum(lam, 0.0))
    smax, sminr = s[:, -1], s[:, 0]
    smin = np.maximum(sminr, smax / RCN_MAX)
    Ue = U[:, :, [m - 1, 0]]  # (f, m, 2): u of σ_max and of σ_min
    V = np.matmul(ws.Jm.transpose(0, 2, 1), Ue)  # (f, n, 2): J_Sᵀ u
    # v = J_Sᵀu / σ, normalised by its own length: finite (and unit) even where σ_min ≈ 0,
    # so the step keeps a direction and is capped as planner.mda's (not dropped)
    norms = np.sqrt(np.einsum("fns,fns->fs", V, V))
    V /= np.where(norms > 0.0, norms, 1.0)[:, None, :]
    X = np.matmul(dJ.reshape(n * m, n), V).reshape(-1, n, m, 2)  # (∂J/∂q_j) v
    D = np.einsum("fjms,fms->fjs", X, Ue)  # (f, n, 2): ∂σ_max/∂q_j, ∂σ_min/∂q_j
    live = sminr > smax / RCN_SINGULAR  # singular reduced robots add nothing (eq. S1)
    smin = np.where(live, smin, 1.0)
    k = np.where(live, smax / smin, 0.0)
    return (2.0 * k / smin) @ D[:, :, 0] - (2.0 * k * smax / smin**2) @ D[:, :, 1]
