"""Whole-path planner: the DP is exact on its grid, plans keep the task and the limits,
and from the same start the plan's mean jump is never above LNVA's and JVJA's."""

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.errors import InvalidInput
from fault_tolerance.paper.cases import CASES
from fault_tolerance.planning.posture import inverse_kinematics
from fault_tolerance.planning.wholepath.dp import (
    brute_force,
    node_data,
    solve_banded,
    stage_edges,
    trace_stages,
)
from fault_tolerance.planning.wholepath.plan import plan_path
from fault_tolerance.planning.wholepath.problem import (
    build_problem,
    kinematics,
    rollout,
)
from fault_tolerance.planning.wholepath.scp import scp
from fault_tolerance.simulation.paths import CirclePath

#: A dexterous start of Fig. 7 (on the self-motion of its x0).
FIG7_Q0 = np.array([0.2574, 1.2106, -0.9513, 1.9333])


def _fig7(duration=0.3):
    case = CASES["fig7"]
    arm = ft.load_arm(case.robot)
    q0 = inverse_kinematics(arm, np.array(case.x0), FIG7_Q0)
    return arm, case.path(duration), q0, list(case.lockable)


def _random_graph(rng, sizes, nb, holes=0.2):
    costs, targets = [], []
    for s in range(len(sizes) - 1):
        c = rng.uniform(0, 1, (sizes[s], nb))
        t = rng.integers(0, sizes[s + 1], (sizes[s], nb))
        cut = rng.uniform(size=c.shape) < holes
        costs.append(np.where(cut, np.inf, c))
        targets.append(np.where(cut, -1, t))
    return costs, targets


@pytest.mark.parametrize("objective", ["mean", "max"])
@pytest.mark.parametrize("start", [None, 0, 2])
def test_dp_equals_brute_force_on_random_graphs(objective, start):
    """Backward DP finds the same optimum as enumerating every node sequence."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        sizes = list(rng.integers(3, 6, size=int(rng.integers(2, 5))))
        costs, targets = _random_graph(rng, sizes, int(rng.integers(1, 4)))
        seq, value = solve_banded(costs, targets, start=start, objective=objective)
        assert value == pytest.approx(brute_force(costs, targets, start, objective), abs=1e-12)
        if np.isfinite(value):  # the sequence it returns costs what it says
            vals = []
            for s in range(len(costs)):
                b = int(np.flatnonzero(targets[s][seq[s]] == seq[s + 1])[0])
                cand = costs[s][seq[s]][targets[s][seq[s]] == seq[s + 1]]
                vals.append(cand.min())
                assert b >= 0
            total = sum(vals) if objective == "mean" else max(vals)
            assert total == pytest.approx(value, abs=1e-12)


@pytest.mark.parametrize("objective", ["mean", "max"])
def test_dp_equals_brute_force_on_a_self_motion_grid(objective):
    """On a coarse self-motion grid of the spatial 4R the DP equals brute-force enumeration."""
    arm, path, q0, lockable = _fig7(0.02)
    prob = build_problem(arm, path, dt=1e-3, steps=20, lockable=lockable, objective=objective)
    ks = np.array([0, 10, 20])
    stages = trace_stages(prob, ks, np.array([q0] * 3), h=0.6, max_nodes=40, subdivide=1)
    assert all(4 <= len(st.q) <= 40 for st in stages)
    nds = [node_data(prob, st) for st in stages]
    edges = [stage_edges(prob, stages[s], nds[s], stages[s + 1], nds[s + 1], 2) for s in (0, 1)]
    costs, targets = [e[0] for e in edges], [e[1] for e in edges]
    _, value = solve_banded(costs, targets, objective=objective)
    assert np.isfinite(value)
    assert value == pytest.approx(brute_force(costs, targets, None, objective), rel=1e-12)


def test_self_motion_nodes_reach_the_task_point():
    """Every node of a traced stage reaches x_des at its stage time."""
    arm, path, q0, lockable = _fig7(0.1)
    prob = build_problem(arm, path, dt=1e-3, steps=100, lockable=lockable)
    (st,) = trace_stages(prob, np.array([50]), q0[None], h=0.02, max_nodes=2000)
    _, E = kinematics(prob, st.q, np.full(len(st.q), 50))
    assert np.max(np.linalg.norm(E, axis=1)) < 1e-9
    if np.isfinite(st.period):  # a closed curve: it ends next to where it began
        assert np.linalg.norm(st.q[-1] - st.q[0]) < 0.05
    else:  # an arc: both ends next to a position limit (±π here)
        for end in (st.q[0], st.q[-1]):
            assert np.min(np.minimum(end - prob.lower, prob.upper - end)) < 0.1
    assert np.all((st.q >= prob.lower) & (st.q <= prob.upper))


def _task_residual(prob, traj):
    J, E = kinematics(prob, traj.q, np.arange(len(traj.q)))
    xd = prob.xd_des + prob.feedback_gain * E
    return np.max(np.abs(np.einsum("kmn,kn->km", J, traj.qd) - xd))


@pytest.mark.parametrize("gain", [0.0, 10.0])
def test_plan_keeps_the_task_and_the_limits_at_every_step(gain):
    """J q̇_k = ẋ_cmd,k at every step (with and without task feedback) and no limit is violated."""
    arm, path, q0, lockable = _fig7(0.3)
    plan = plan_path(arm, path, q0=q0, lockable=lockable, feedback_gain=gain)
    prob = build_problem(arm, path, dt=1e-3, steps=300, lockable=lockable, feedback_gain=gain)
    traj = rollout(prob, q0, "track", q_ref=plan.q_ref)
    np.testing.assert_allclose(traj.q, plan.q_ref, atol=1e-9)
    assert _task_residual(prob, traj) < 1e-10
    assert traj.violation == 0.0
    assert plan.info["violations"][plan.method.replace("warm start (", "").rstrip(")")] == 0.0


def test_fixed_start_is_respected_exactly():
    """With q0 given, the plan starts at q0 bit for bit."""
    arm, path, q0, lockable = _fig7(0.2)
    plan = plan_path(arm, path, q0=q0, lockable=lockable)
    assert np.array_equal(plan.q0, q0) and np.array_equal(plan.q_ref[0], q0)
    assert plan.fixed_start


def test_plan_beats_lnva_and_jvja_from_the_same_start():
    """Fig. 7 (JVJA above LNVA): the plan's mean jump is below both, and says by how much."""
    arm, path, q0, lockable = _fig7(0.5)
    plan = plan_path(arm, path, q0=q0, lockable=lockable)
    s = plan.scores
    assert s["final"] < min(s["lnva"], s["jvja"])
    assert plan.improvement == pytest.approx((s[plan.warm_start] - s["final"]) / s[plan.warm_start])
    assert plan.method in ("dp+scp", "scp", "dp")


def test_free_start_lies_on_the_self_motion_of_x0():
    """Without q0 the start is free on x(q) = x0, and the plan is at least as good as the local runs."""
    arm, path, _, lockable = _fig7(0.3)
    plan = plan_path(arm, path, lockable=lockable)
    assert np.linalg.norm(arm.task_error(path.x(0.0), plan.q0)) < 1e-9
    assert plan.scores["final"] <= min(plan.scores["lnva"], plan.scores["jvja"])


@pytest.mark.parametrize("objective", ["mean", "max"])
def test_scp_is_never_worse_than_its_warm_start(objective):
    """SCP returns its best feasible iterate: objective at most the warm start's."""
    arm, path, q0, lockable = _fig7(0.2)
    prob = build_problem(arm, path, dt=1e-3, steps=200, lockable=lockable, objective=objective)
    warm = rollout(prob, q0, "lnva")
    out = scp(prob, warm, iterations=4)
    assert out.best.score <= warm.score
    assert out.history == sorted(out.history, reverse=True)


def test_velocity_limits_are_kept_when_they_bind():
    """A velocity bound the local runs exceed: the plan keeps it (or says it could not)."""
    arm, path, q0, lockable = _fig7(0.2)
    prob = build_problem(arm, path, dt=1e-3, steps=200, lockable=lockable)
    ln = rollout(prob, q0, "lnva")
    vmax = 1.2 * np.abs(ln.qd).max(axis=0)
    jv = rollout(prob, q0, "jvja")
    assert np.any(np.abs(jv.qd) > vmax)  # JVJA breaks this bound, LNVA keeps it
    tight = prob.__class__(**{**prob.__dict__, "vmax": vmax})
    out = scp(tight, rollout(tight, q0, "lnva"), iterations=4)
    assert out.best.violation == 0.0
    assert np.all(np.abs(out.best.qd) <= vmax)


def test_bad_options_are_refused():
    """Unknown method / objective, dp for r > 1 and a free start off the path raise InvalidInput."""
    arm, path, q0, lockable = _fig7(0.05)
    with pytest.raises(InvalidInput, match="method"):
        plan_path(arm, path, q0=q0, lockable=lockable, method="bfgs")
    with pytest.raises(InvalidInput, match="objective"):
        plan_path(arm, path, q0=q0, lockable=lockable, objective="median")
    with pytest.raises(InvalidInput, match="x0"):
        plan_path(arm, path, x0=np.zeros(3), lockable=lockable)
    panda = ft.load_arm("panda", task="position")
    p2 = CirclePath(panda.fk(panda.q_reference), 0.05, 2 * np.pi, 0.05, rows=(0, 1))
    with pytest.raises(InvalidInput, match="one degree of redundancy"):
        plan_path(panda, p2, q0=panda.q_reference, method="dp")


# -- the claims on every case (slow) --------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("key", sorted(CASES))
def test_paper_cases_global_not_above_local(key):
    """On each paper case, from the minimum-RCN start, mean λ(global) ≤ LNVA's and JVJA's."""
    from fault_tolerance.planning.posture import initial_posture

    case = CASES[key]
    arm = ft.load_arm(case.robot)
    q0 = initial_posture(arm, np.array(case.x0), lockable=list(case.lockable)).q
    plan = plan_path(arm, case.path(), q0=q0, lockable=list(case.lockable))
    s = plan.scores
    assert s["final"] <= min(s["lnva"], s["jvja"])
    assert plan.info["violations"][_cand(plan)] == 0.0


def _cand(plan):
    return plan.method.replace("warm start (", "").rstrip(")")


EXAMPLE_STARTS = {
    ("panda", "pose"): np.array([0.0, -0.4, 0.0, -2.0, 0.0, 1.8, 0.8]),
    ("panda", "position"): np.array([0.0, -0.4, 0.0, -2.0, 0.0, 1.8, 0.8]),
    ("ur5", "position"): np.array([0.3, -1.2, 1.5, -1.2, -1.4, 0.2]),
}


@pytest.mark.slow
@pytest.mark.parametrize("robot,task", sorted(EXAMPLE_STARTS))
def test_example_robot_arms_global_not_above_local(robot, task):
    """Panda pose (r = 1) and position (r = 4), UR5 position (r = 3): the plan beats the local runs."""
    arm = ft.load_arm(robot, task=task)
    q0 = EXAMPLE_STARTS[(robot, task)]
    x0 = arm.fk(q0)
    path = CirclePath(x0, 0.05, 2 * np.pi, 1.0, rows=(0, 1))
    plan = plan_path(arm, path, q0=q0)
    s = plan.scores
    assert s["final"] <= min(s["lnva"], s["jvja"])
    assert plan.info["violations"][_cand(plan)] == 0.0
    assert np.array_equal(plan.q0, q0)


# -- simulate(..., "global"), the CLI ---------------------------------------------------------


def test_simulate_global_is_a_run_like_the_others():
    """simulate(arm, path, "global") tracks the path as LNVA does and its mean jump is not above theirs."""
    from fault_tolerance.simulation.simulate import simulate

    arm, path, q0, lockable = _fig7(0.3)
    runs = {a: simulate(arm, path, a, q0=q0, lockable=lockable) for a in ("lnva", "jvja", "global")}
    g = runs["global"]
    assert g.meta["algorithm"] == "global" and g.meta["global"]["method"]
    assert np.array_equal(g.q[0], q0)
    assert g.summary()["jvj_mean"] <= min(r.summary()["jvj_mean"] for r in runs.values())
    assert (
        g.summary()["tracking_error_max"] < 2 * runs["lnva"].summary()["tracking_error_max"] + 1e-6
    )
    J = np.array([arm.jacobian(q) for q in g.q])
    xd = np.array([path.xdot(t) for t in g.t])
    assert np.max(np.abs(np.einsum("kmn,kn->km", J, g.qd) - xd)) < 1e-9


def test_simulate_global_free_start_and_lock():
    """Without q0 the global plan picks its start at the path's first point; a lock run works too."""
    from fault_tolerance.simulation.simulate import simulate

    arm, path, q0, lockable = _fig7(0.2)
    free = simulate(arm, path, "global", lockable=lockable)
    assert np.linalg.norm(arm.task_error(path.x(0.0), free.q[0])) < 1e-9
    lock = simulate(
        arm, path, "global", q0=q0, lockable=lockable, lock_joint="joint2", lock_time=0.1
    )
    assert lock.meta["lock"]["joint"] == "joint2"
    assert np.all(lock.qd[lock.t >= 0.1, 1] == 0.0)


def test_simulate_refuses_plan_options_elsewhere_and_a_missing_q0():
    """plan_options only with global; q0 required for the local planners; unknown options refused."""
    from fault_tolerance.simulation.simulate import simulate

    arm, path, q0, lockable = _fig7(0.05)
    with pytest.raises(InvalidInput, match="plan_options"):
        simulate(arm, path, "jvja", q0=q0, plan_options={"objective": "max"})
    with pytest.raises(InvalidInput, match="needs q0"):
        simulate(arm, path, "lnva")
    with pytest.raises(InvalidInput, match="not known"):
        simulate(arm, path, "global", q0=q0, plan_options={"speed": 3})


def test_cli_simulate_global(tmp_path, capsys):
    """fault-tolerance simulate --algorithms lnva,jvja,global writes a global run and prints it."""
    from fault_tolerance.cli import main

    rc = main(
        ["simulate", "--robot", "spatial_4r", "--x0=-0.21,0.20,0.35", "--duration", "0.2",
         "--algorithms", "lnva,jvja,global", "--no-progress", "--out", str(tmp_path)]
    )  # fmt: skip
    assert rc == 0
    assert (tmp_path / "global" / "run.npz").is_file()
    assert "global" in capsys.readouterr().out
    assert (
        main(["simulate", "--robot", "spatial_4r", "--algorithms", "gloabl", "--no-progress"]) == 2
    )
