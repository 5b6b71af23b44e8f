"""The Controller's MDA step and the simulated MDA sample against the reference resolution/mda.py."""

from __future__ import annotations

import numpy as np
import pytest
from real_arms import load

import fault_tolerance as ft
from fault_tolerance.control.controller import Controller
from fault_tolerance.resolution.indices import RCN_SINGULAR, rcn_gradient
from fault_tolerance.simulation.paths import CirclePath

SEED = 20240521


def _reference(arm, q, xd, sc):
    return ft.resolve("mda", arm.jacobian(q), xd, lockable=sc, arm=arm, q=q)


def _configurations(arm, rng, count=12, near=3):
    """Random configurations inside the limits, and ``near`` near reduced singularities.

    Near-singular: a configuration pulled towards one where some ``k_S`` exceeds 300 (found by
    shrinking one joint angle towards 0, where links fall in line on the shipped arms).
    """
    qs = [arm.random_q(rng) for _ in range(count)]
    for _ in range(near):
        q = arm.random_q(rng)
        q[-1] = 2e-3 * rng.uniform(0.5, 1.0)
        qs.append(q)
    return qs


def _check_arm(arm, lockable, rng, tol=1e-9):
    ctrl = Controller(arm, lockable, method="mda", backend="numba", limits=False)
    for q in _configurations(arm, rng):
        xd = rng.standard_normal(arm.m)
        ref = _reference(arm, q, xd, ctrl.scenarios)
        got = ctrl.mda(q, xd)
        np.testing.assert_allclose(got, ref, rtol=0, atol=tol * max(1.0, np.abs(ref).max()))


@pytest.mark.parametrize(
    "name, kw, lockable",
    [
        ("planar_3r", {}, "all"),
        ("spatial_4r", {}, [0, 1, 2]),
        ("panda", {"task": "pose"}, [0, 1, 2, 4, 5, 6]),
        ("panda", {"task": "position"}, "all"),
    ],
)
def test_controller_mda_equals_the_reference(name, kw, lockable):
    """Controller(method='mda', backend='numba') rates equal ft.resolve('mda') to 1e-9."""
    _check_arm(ft.load_arm(name, **kw), lockable, np.random.default_rng(SEED))


def test_controller_mda_on_a_real_arm():
    """The same on a real description from tests/data (Kinova, position task)."""
    arm = load("kinova")
    _check_arm(arm, "all", np.random.default_rng(SEED + 1))


def test_near_singular_configurations_are_near_singular():
    """The near-singular pool of planar_3r does reach k_S > 300 (the test above covers them)."""
    arm = ft.load_arm("planar_3r")
    qs = _configurations(arm, np.random.default_rng(SEED), count=0, near=3)
    assert min(ft.rcn(arm.jacobian(q), "all").max() for q in qs) > 300


# -- exact reduced singularities (eq. S1) ---------------------------------------------------


def _routes(arm, q, xd, lockable):
    """The MDA rates of every route at (q, xd)."""
    out = {"resolve": _reference(arm, q, xd, lockable)}
    for backend in ("numba", "numpy"):
        ctrl = Controller(arm, lockable, method="mda", backend=backend, limits=False)
        out[backend] = ctrl.mda(q, xd)
    return out


@pytest.mark.parametrize(
    "name, kw, q",
    [
        ("planar_3r", {}, [0.3, 1.2, 0.0]),  # links 2, 3 in line: locking joint 1 is singular
        ("spatial_4r", {}, None),
    ],
)
def test_every_route_takes_one_direction_at_an_exact_reduced_singularity(name, kw, q):
    """At σ_min(J_S) = 0 the null steps of ft.resolve and the Controller (all backends) agree."""
    arm = ft.load_arm(name, **kw)
    lockable = "all" if name == "planar_3r" else [0, 1, 2]
    q = np.asarray(q, dtype=float) if q is not None else _singular_spatial(arm)
    J, dJ = arm.jacobian(q), arm.jacobian_derivatives(q)
    s = [np.linalg.svd(np.delete(J, i, axis=1), compute_uv=False) for i in range(arm.n)]
    assert min(v[-1] / v[0] for v in s) < 1e-12 < 1.0 / RCN_SINGULAR  # exactly singular
    xd = np.full(arm.m, 0.1)
    a = np.linalg.pinv(J) @ xd
    routes = _routes(arm, q, xd, lockable)
    ref = routes["resolve"] - a
    assert np.linalg.norm(ref) > 1e-6  # the other reduced robots give a direction
    for name_, qd in routes.items():
        step = qd - a
        np.testing.assert_allclose(
            step, ref, rtol=0, atol=1e-9 * np.linalg.norm(ref), err_msg=name_
        )
    g = rcn_gradient(J, dJ, lockable if lockable != "all" else None)
    assert np.all(np.isfinite(g))


def _singular_spatial(arm):
    """A spatial_4r configuration where joints 2-4 alone (joint 1 locked) are singular: q3 = 0."""
    return np.array([0.4, 0.7, 0.0, 0.9])


def test_simulate_follows_the_reference_near_a_reduced_singularity():
    """The compiled simulated sample equals the reference run near σ_min(J_S) = 0.

    At an exact one a planar 3R scenario is intolerable (r = 1: J_S singular iff N_ii = 0), which
    simulate refuses; near it (k_S > 300) the run is the reference's to 1e-9.
    """
    arm = ft.load_arm("planar_3r")
    q0 = np.array([0.3, 1.2, 0.005])
    assert ft.rcn(arm.jacobian(q0), "all").max() > 300
    path = CirclePath(arm.fk(q0), 0.01, 2 * np.pi, 0.05, rows=(0, 1))
    runs = [
        ft.simulate(arm, path, "mda", q0=q0, lockable="all", limits=False, engine=engine)
        for engine in ("fast", "reference")
    ]
    np.testing.assert_allclose(runs[0].qd, runs[1].qd, rtol=0, atol=1e-9)
    np.testing.assert_allclose(runs[0].K, runs[1].K, rtol=1e-9)


def test_the_posture_descent_escapes_a_singular_reduced_robot():
    """singular="escape" keeps the capped term: at an exactly singular J_S a small step against
    it lowers K (the skipped term would leave the descent stuck there). Unknown values raise."""
    arm = ft.load_arm("planar_3r")
    q = np.array([0.3, 1.0, 0.0])  # joint 1 locked: links 2-3 aligned, J_S singular
    J, dJ = arm.jacobian(q), arm.jacobian_derivatives(q)
    g = rcn_gradient(J, dJ, "all", singular="escape")
    skipped = rcn_gradient(J, dJ, "all")
    assert np.linalg.norm(g) > 1e6 * np.linalg.norm(skipped)
    step = 1e-3 * g / np.linalg.norm(g)
    assert ft.square_sum_rcn(arm.jacobian(q - step), "all") < ft.square_sum_rcn(J, "all")
    with pytest.raises(ft.InvalidInput, match="allowed: skip, escape"):
        rcn_gradient(J, dJ, "all", singular="ignore")
