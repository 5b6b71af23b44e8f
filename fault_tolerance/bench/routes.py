"""The generic-solver routes the benchmark times against the fast path: eqs. (3)-(4) as a QP."""

from __future__ import annotations

import numpy as np

from fault_tolerance.numerics.linalg import reduced_rates_explicit


def post_failure_rates_explicit(J: np.ndarray, xdot: np.ndarray, sc) -> np.ndarray:
    """Eq. (2) for every scenario, one pseudo-inverse each (what a generic route has to do)."""
    return np.array([reduced_rates_explicit(J, xdot, S) for S in sc.sets])


# Eqn. (3)-(4) by a QP solver.
def jvja_qp(J: np.ndarray, xdot: np.ndarray, sc) -> np.ndarray:
    r"""JVJA as a QP, eqs. (3)-(4) handed to ``quadprog`` (a dense active-set solver).

    :math:`\min \tfrac12 W\|\dot q\|^2 - (\sum_S w_S\,{}^S\dot q')^T\dot q` s.t.
    :math:`J\dot q = \dot x`, which is (3) up to a constant; ``ˢq̇'`` from eq. (2) per scenario.
    """
    import quadprog

    m, n = J.shape
    post = post_failure_rates_explicit(J, xdot, sc)
    H = sc.weights.sum() * np.eye(n)
    g = sc.weights @ post
    return quadprog.solve_qp(H, g, J.T, xdot, m)[0]


def jvja_slsqp(J: np.ndarray, xdot: np.ndarray, sc) -> np.ndarray:
    """JVJA as eqs. (3)-(4) handed to ``scipy.optimize.minimize(method="SLSQP")`` from q̇ = 0."""
    from scipy.optimize import minimize

    n = J.shape[1]
    post = post_failure_rates_explicit(J, xdot, sc)
    W = float(sc.weights.sum())
    g = sc.weights @ post
    res = minimize(
        lambda x: 0.5 * W * (x @ x) - g @ x,
        np.zeros(n),
        jac=lambda x: W * x - g,
        constraints=[{"type": "eq", "fun": lambda x: J @ x - xdot, "jac": lambda x: J}],
        method="SLSQP",
        options={"ftol": 1e-14, "maxiter": 200},
    )
    return res.x


def installed(module: str) -> bool:
    """Whether ``module`` can be imported here."""
    try:
        __import__(module)
        return True
    except ImportError:
        return False


_installed = installed  # the old private name
