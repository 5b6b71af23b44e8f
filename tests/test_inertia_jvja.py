"""resolution/inertia_jvja.py: the minimum kinetic-energy jump against direct minimisations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

import fault_tolerance as ft
from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.dynamics import ArmDynamics
from fault_tolerance.resolution.inertia_jvja import inertia_projector, jvja_inertia, kinetic_jumps


def _problem(m: int, n: int, seed: int):
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(m, n))
    B = rng.normal(size=(n, n))
    M = B @ B.T + 0.5 * np.eye(n)
    return J, rng.normal(size=m), M


def _jump_kkt(J, M, qd, S) -> np.ndarray:
    """Δ_S of (D1) by an explicit KKT solve: min ½ΔᵀMΔ s.t. JΔ = 0, Δ[S] = −q̇[S]."""
    n = len(qd)
    E = np.eye(n)[list(S)]
    A = np.vstack([J, E])
    kkt = np.block([[M, A.T], [A, np.zeros((len(A), len(A)))]])
    rhs = np.concatenate([np.zeros(n), np.zeros(len(J)), -qd[list(S)]])
    return np.linalg.solve(kkt, rhs)[:n]


def _energy(J, M, qd, sets, w) -> float:
    return sum(
        wS * 0.5 * _jump_kkt(J, M, qd, S) @ M @ _jump_kkt(J, M, qd, S)
        for S, wS in zip(sets, w, strict=True)
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rates_minimise_the_kinetic_energy_jump_over_the_task_set(seed):
    """(D3) equals a direct scipy minimisation of Σ_S w_S ½Δ_SᵀMΔ_S over q̇ = a + Nz (r = 3)."""
    J, xd, M = _problem(2, 5, seed)
    sets, w = [(0,), (2,), (3, 4)], [1.0, 2.0, 0.5]
    qd = jvja_inertia(J, xd, sets, M=M, weights=w)
    np.testing.assert_allclose(J @ qd, xd, atol=1e-10)
    a = np.linalg.pinv(J) @ xd
    Z = np.linalg.svd(J)[2][2:].T  # basis of the null space
    res = minimize(lambda y: _energy(J, M, a + Z @ y, sets, w), np.zeros(3), method="BFGS",
                   options={"gtol": 1e-12})  # fmt: skip
    np.testing.assert_allclose(qd, a + Z @ res.x, atol=1e-6)
    assert _energy(J, M, qd, sets, w) <= res.fun + 1e-12


def test_kinetic_jumps_are_the_kkt_energies():
    """(D2): ½ q̇[S]ᵀÑ[S,S]⁻¹q̇[S] equals the energy of the KKT jump, and JÑ = 0."""
    J, xd, M = _problem(3, 6, 3)
    qd = np.random.default_rng(4).normal(size=6)
    sets = [(1,), (2, 5)]
    direct = [0.5 * _jump_kkt(J, M, qd, S) @ M @ _jump_kkt(J, M, qd, S) for S in sets]
    np.testing.assert_allclose(kinetic_jumps(J, qd, M, sets), direct, rtol=1e-10)
    np.testing.assert_allclose(J @ inertia_projector(J, M), 0.0, atol=1e-12)


def test_identity_inertia_is_the_continuation_jvja():
    """With M = I, (D3) is (G3): JVJA with the continuation response."""
    J, xd, _ = _problem(2, 5, 5)
    np.testing.assert_allclose(
        jvja_inertia(J, xd, [0, 1, 3], M=np.eye(5)),
        ft.jvja(J, xd, [0, 1, 3], response="continuation"),
        atol=1e-10,
    )


@pytest.mark.parametrize("seed", [6, 7])
def test_one_degree_of_redundancy_gives_jvja(seed):
    """(D4): for r = 1 the inertia weighting leaves JVJA's rates unchanged, whatever M."""
    J, xd, M = _problem(3, 4, seed)
    np.testing.assert_allclose(jvja_inertia(J, xd, [0, 1, 2], M=M), ft.jvja(J, xd, [0, 1, 2]),
                               atol=1e-10)  # fmt: skip


def test_differs_from_jvja_when_r_is_two_or_more():
    """For r ≥ 2 and a non-uniform M the inertia-weighted rates are not JVJA's (it can fail)."""
    J, xd, M = _problem(2, 5, 8)
    assert np.linalg.norm(jvja_inertia(J, xd, None, M=M) - ft.jvja(J, xd, None)) > 1e-3


def test_resolve_takes_the_inertia_from_the_arm():
    """ft.resolve('jvja_inertia', arm=, q=) uses the arm's M(q); without M or arm it says so."""
    arm = ft.load_arm("panda", task="position")
    q = arm.q_reference + 0.1
    J, xd = arm.jacobian(q), np.array([0.05, -0.02, 0.03])
    M = ArmDynamics(arm).mass_matrix(q)
    np.testing.assert_allclose(
        ft.resolve("jvja_inertia", J, xd, lockable=[1, 3], arm=arm, q=q),
        jvja_inertia(J, xd, [1, 3], M=M),
        atol=1e-12,
    )
    with pytest.raises(InvalidInput, match="needs the configuration.*M="):
        ft.resolve("jvja_inertia", J, xd, lockable=[1, 3])


def test_bounded_inertia_jvja_minimises_inside_the_box():
    """Under a box that binds, the bounded rates equal SLSQP's minimum of ½q̇ᵀHq̇ s.t. Jq̇ = ẋ, box."""
    J, xd, M = _problem(2, 5, 9)
    sets = [(0,), (1,), (4,)]
    free = jvja_inertia(J, xd, sets, M=M)
    hi = np.full(5, np.inf)
    j = int(np.argmax(free))
    hi[j] = 0.8 * free[j]
    lo = np.full(5, -np.inf)
    out = ft.resolve_bounded("jvja_inertia", J, xd, sets, bounds=(lo, hi), M=M)
    assert out.qd[j] <= hi[j] + 1e-9 and out.scale == pytest.approx(1.0)
    np.testing.assert_allclose(J @ out.qd, xd, atol=1e-9)
    res = minimize(
        lambda v: sum(kinetic_jumps(J, v, M, sets)), free, method="SLSQP",
        constraints=[{"type": "eq", "fun": lambda v: J @ v - xd}],
        bounds=[(None, h if np.isfinite(h) else None) for h in hi], options={"ftol": 1e-14},
    )  # fmt: skip
    np.testing.assert_allclose(out.qd, res.x, atol=1e-5)
    inside = ft.resolve_bounded("jvja_inertia", J, xd, sets, bounds=(lo, np.full(5, np.inf)), M=M)
    np.testing.assert_allclose(inside.qd, free, atol=1e-12)


@pytest.mark.parametrize("limits", [False, True])
def test_controller_step_equals_the_resolver(limits):
    """Controller(method='jvja_inertia') gives ft.resolve's rates (bounded: resolve_bounded's)."""
    arm = ft.load_arm("panda", task="position")
    ctrl = ft.Controller(arm, [1, 3, 5], method="jvja_inertia", limits=limits)
    q, xd = arm.q_reference + 0.2, np.array([0.05, -0.02, 0.03])
    M = ArmDynamics(arm).mass_matrix(q)
    J = arm.jacobian(q)
    if limits:
        box = ft.rate_box(q, arm.lower, arm.upper, arm.velocity_limit)
        want = ft.resolve_bounded("jvja_inertia", J, xd, [1, 3, 5], bounds=box, M=M).qd
    else:
        want = jvja_inertia(J, xd, [1, 3, 5], M=M)
    np.testing.assert_allclose(ctrl.step(q, xd), want, atol=1e-10)
    with pytest.raises(InvalidInput):
        ctrl.step(q, np.zeros(2))


def test_registered_like_the_other_resolvers():
    """Its registry entry: bounded variant, needs the configuration, options checked, M as context."""
    from fault_tolerance.resolution import registry
    from fault_tolerance.resolution.inertia_jvja import JvjaInertiaOptions, bounded_jvja_inertia

    entry = registry.get("jvja_inertia")
    assert entry.bounded is bounded_jvja_inertia and entry.options is JvjaInertiaOptions
    assert entry.needs_configuration and entry.compiled is None and entry.colour.startswith("#")
    J, xd, M = _problem(2, 5, 3)
    np.testing.assert_allclose(
        ft.resolve("jvja_inertia", J, xd, [0, 1], M=M), jvja_inertia(J, xd, [0, 1], M=M), atol=1e-12
    )
    with pytest.raises(InvalidInput, match="unknown option"):
        ft.resolve("jvja_inertia", J, xd, [0, 1], M=M, response="continuation")
