"""What the benchmark times: its arms, the configuration pool, and the rows of each arm.

The rows come in groups (:data:`GROUPS`): each group is a label, a function that builds its rows
from a :class:`Case` (one arm, its controller and the pool) and the divisor of ``--steps`` for its
rows. A new row goes into a builder; a new kind of row may be a new group.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fault_tolerance.bench.routes import installed, jvja_qp, jvja_slsqp, post_failure_rates_explicit
from fault_tolerance.bench.scaled_rows import DESCRIPTIONS as SCALED_DESCRIPTIONS
from fault_tolerance.bench.timing import Row, stats, time_rows
from fault_tolerance.errors import InvalidInput

if TYPE_CHECKING:
    from fault_tolerance.control.controller import Controller
    from fault_tolerance.model.arm import Arm

#: The benchmark's arms: robot, task and lockable set.
ARMS: dict[str, dict] = {
    "planar_3r": {"robot": "planar_3r", "task": None, "lockable": "all"},
    "spatial_4r": {"robot": "spatial_4r", "task": None, "lockable": ["joint1", "joint2", "joint3"]},
    "panda_pose": {"robot": "panda", "task": "pose", "lockable": "all"},
    "panda_position": {"robot": "panda", "task": "position", "lockable": "all"},
    "powercube_3r": {"robot": "powercube_3r", "task": None, "lockable": "all"},
    **{
        f"chain_{n}": {"robot": f"chain_{n}", "task": "pose", "lockable": "all", "chain": n}
        for n in (7, 14, 30, 50)
    },
}
#: The synthetic chains of the scaling table (``bench.chain``).
CHAIN_ARMS = ("chain_7", "chain_14", "chain_30", "chain_50")
#: Arms run when ``--robots`` is not given.
DEFAULT_ARMS = ("planar_3r", "spatial_4r", "panda_pose", "panda_position")
POOL = 64
SEED = 20240521

DESCRIPTIONS = {
    "jacobian": "task Jacobian (Pinocchio computeFrameJacobian)",
    "floor": "Jacobian + compiled least-norm solve (Cholesky of J Jᵀ, no check): the floor",
    "jvja_multi": "JVJA step, two-joint scenarios (j, j+1) (Jacobian included)",
    "sim_jvja": "one simulated JVJA sample: rates, λ parts, k_S, K, σ_min, flags, record",
    "sim_lnva": "one simulated LNVA sample: rates, λ parts, k_S, K, σ_min, flags, record",
    "sim_jvja_lim": "one simulated JVJA sample under joint limits (rate box checked; default)",
    "jvja_bounded_run": "bounded JVJA step (Controller, limits on) at the samples of the sim_jvja_lim "
    "run",
    "sim_mda": "one simulated MDA sample (∇K compiled): rates, λ parts, k_S, K, σ_min, flags",
    "lnva": "LNVA step, fast path (Jacobian included)",
    "jvja": "JVJA step, closed form G2, fast path (Jacobian included)",
    "rcn": "RCN of all scenarios, one batched eigvalsh (Jacobian included)",
    "mda": "MDA step, compiled (Jacobian, ∇K from the kinematic Hessian, null step included)",
    "mda_gradient": "Jacobian + ∇K alone (the MDA kernel's gradient, no least-norm rates, no null "
    "step)",
    "lnva_resolve": "arm.jacobian + ft.resolve('lnva')",
    "jvja_resolve": "arm.jacobian + ft.resolve('jvja')",
    "mda_resolve": "ft.resolve('mda', arm=, q=) with arm.jacobian(_derivatives)",
    "rcn_resolve": "arm.jacobian + ft.rcn",
    "jvja_explicit": "Jacobian + eq. (5), one pseudo-inverse per scenario (planner.jvja_explicit)",
    "jvja_qp": "Jacobian + eq. (2) per scenario + (3)-(4) by quadprog (dense active-set QP)",
    "qp_solve_only": "the quadprog call alone, its inputs (J, ẋ, Σ w ˢq̇') given",
    "jvja_slsqp": "Jacobian + eq. (2) per scenario + (3)-(4) by scipy.optimize SLSQP",
    "jvja_bounded_free": "JVJA step with joint limits on, no bound active (fast step + box check)",
    "jvja_bounded_2": "JVJA step with joint limits on, two joints at a binding bound (bounded QPs)",
    "jvja_bounded_2_qp": "the same bounded JVJA problem by quadprog (f reduced QPs + 1)",
    **SCALED_DESCRIPTIONS,
    "dyn_sample": "one dynamics sample: computed-torque law (RNEA + PD), saturation, one ABA "
    "semi-implicit Euler step (simulation.torque.control_step)",
}


@dataclass
class Case:
    """One benchmark arm ready to time: the arm, its controller, the pool of (q, ẋ)."""

    key: str
    spec: dict
    arm: Arm
    ctrl: Controller
    qs: list
    xds: list
    out: np.ndarray  # an (n,) output buffer shared by the rows

    @property
    def sc(self):
        """The controller's failure scenarios."""
        return self.ctrl.scenarios

    @property
    def qx(self) -> list[tuple]:
        """``(q, ẋ)`` pairs of the pool."""
        return list(zip(self.qs, self.xds, strict=True))

    @property
    def qxo(self) -> list[tuple]:
        """``(q, ẋ, out)`` triples of the pool."""
        return [(q, xd, self.out) for q, xd in self.qx]


def _pool(arm, sc, rng: np.random.Generator, size: int) -> tuple[list, list]:
    """Generic configurations inside the joint limits; unit ẋ.

    Full-turn joints are wrapped into their limits; σ_min(J) ≥ 0.01 and every scenario pivot
    ≥ 1e-4.
    """
    from fault_tolerance.model.joint_limits import wrap_into_limits
    from fault_tolerance.numerics.linalg import min_pivot, projection

    qs, xds = [], []
    for _ in range(200 * size):
        q = wrap_into_limits(arm, arm.random_q(rng))
        proj = projection(arm.jacobian(q))
        if proj.sigma_min < 1e-2 or min(min_pivot(proj.N, S) for S in sc.sets) < 1e-4:
            continue
        v = rng.standard_normal(arm.m)
        qs.append(np.ascontiguousarray(q))
        xds.append(v / np.linalg.norm(v))
        if len(qs) == size:
            return qs, xds
    raise InvalidInput(f"{arm.name}: no generic configuration found for the benchmark pool")


def make_case(key: str, backend: str = "auto") -> Case:
    """The arm ``key`` of :data:`ARMS` with its controller and pool."""
    from fault_tolerance.control.controller import Controller
    from fault_tolerance.model.loading import load_arm

    spec = ARMS[key]
    if "chain" in spec:
        from fault_tolerance.bench.chain import synthetic_chain

        arm = synthetic_chain(spec["chain"], spec["task"])
    else:
        arm = load_arm(spec["robot"], **({"task": spec["task"]} if spec["task"] else {}))
    ctrl = Controller(arm, spec["lockable"], backend=backend, limits=False)  # the paper's step
    qs, xds = _pool(arm, ctrl.scenarios, np.random.default_rng(SEED), POOL)
    return Case(key, spec, arm, ctrl, qs, xds, np.empty(arm.n))


# -- the rows, by group ------------------------------------------------------------------------


def fast_rows(case: Case) -> dict[str, Row]:
    """The controller's steps, and LNVA / JVJA with every other installed backend."""
    from fault_tolerance.control.controller import Controller, available_backends

    ctrl, qxo = case.ctrl, case.qxo
    rows: dict[str, Row] = {
        "jacobian": (ctrl.jacobian, [(q,) for q in case.qs]),
        "lnva": (ctrl.lnva, qxo),
        "jvja": (ctrl.jvja, qxo),
        "rcn": (ctrl.rcn, [(q, np.empty(case.sc.f)) for q in case.qs]),
        "mda": (ctrl.mda, qxo),
    }
    for other in available_backends():
        if other != ctrl.backend:
            c2 = Controller(case.arm, case.spec["lockable"], backend=other, limits=False)
            rows[f"lnva_{other}"] = (c2.lnva, qxo)
            rows[f"jvja_{other}"] = (c2.jvja, qxo)
    if case.arm.redundancy >= 2:  # two-joint scenarios: the general (G1) kernel
        pairs = [(j, j + 1) for j in range(case.arm.n - 1)]
        multi = Controller(case.arm, pairs, backend=ctrl.backend, limits=False)
        rows["jvja_multi"] = (multi.jvja, qxo)
    return rows


def floor_rows(case: Case) -> dict[str, Row]:
    """The floor of a step: Pinocchio's Jacobian and a compiled least-norm solve, nothing else."""
    import pinocchio as pin

    from fault_tolerance.control.fast.step import compiled_kernel

    ctrl, m = case.ctrl, case.arm.m
    kernel, cfj, lwa = compiled_kernel("floor"), pin.computeFrameJacobian, pin.LOCAL_WORLD_ALIGNED
    model, data, fid, sel = ctrl.model, ctrl.model.createData(), ctrl.frame_id, ctrl.workspace.rows
    G, y = np.empty((m, m)), np.empty(m)

    def floor(q, xd, out):
        kernel(cfj(model, data, q, fid, lwa)[sel], xd, out, G, y)
        return out

    return {"floor": (floor, case.qxo)}


def simulated_rows(case: Case) -> dict[str, Row]:
    """One sample of ``simulate`` (the loop body), LNVA, JVJA and MDA, along a 1 s circle of 1 cm.

    The paper's sample (no limits) and JVJA's under the joint limits (simulate's default), each
    sample of one run in order.
    """
    from fault_tolerance.simulation import simulate as sim
    from fault_tolerance.simulation.fast.sampler import Sampler, covers
    from fault_tolerance.simulation.paths import CirclePath

    arm, sc = case.arm, case.sc
    if covers(sc, "jvja", "least_norm") is not None:
        return {}
    q0 = case.qs[0]
    path = CirclePath(arm.fk(q0)[: arm.m], 0.01, 2 * np.pi, 1.0, rows=(0, 1))
    rows: dict[str, Row] = {}
    for alg, limits in (("lnva", False), ("jvja", False), ("jvja", True), ("mda", False)):
        s = sim._setup(arm, path, alg, q0, sc, None, "least_norm", 1e-3, None, 0.0, 1e-2,
                       None, None, None, limits=limits)  # fmt: skip
        rec = sim._allocate(s.steps + 1, arm.n, arm.m, sc.f, s.dt)
        X, XD = sim.sample_path(path, rec["t"], arm.m)
        state = sim._State(q=q0.copy(), qd=np.zeros(arm.n), keep=np.arange(arm.n))
        smp, K1 = Sampler(s, rec), s.steps + 1

        at = np.array([-1])

        def sample(i, s=s, state=state, smp=smp, rec=rec, X=X, XD=XD, K1=K1, q0=q0, at=at):
            """The next sample of one run, in order (the run starts over at its end)."""
            at[0] = k = (int(at[0]) + 1) % K1
            if k == 0:
                state.q, state.qd = q0.copy(), np.zeros(len(q0))
            sim._maybe_lock(s, state, k * s.dt)
            if not smp.step(state, k, X[k], XD[k]):
                sim._step(s, state, k, rec, X[k], XD[k])

        rows[f"sim_{alg}" + ("_lim" if limits else "")] = (sample, [(k,) for k in range(K1)])
        if limits:
            rows["jvja_bounded_run"] = _bounded_run_row(case, s, sample, rec, XD)
    return rows


def _bounded_run_row(case: Case, s, sample, rec, XD) -> Row:
    """The Controller's bounded JVJA step at the samples of the run under limits (its denominator).

    One pass of the run records its configurations; the step is then timed at each ``(q_k, ẋ_k)``
    (the run has no task feedback: ``ẋ_cmd = ẋ_des``), so both sides meet the same bounds.
    """
    from fault_tolerance.control.controller import Controller

    K1 = len(XD)
    for k in range(K1):
        sample(k)
    ctrl = Controller(case.arm, case.sc, method="jvja", tolerate=True, backend=case.ctrl.backend,
                      limits=True, horizon=s.horizon)  # fmt: skip
    qs = rec["q"].copy()
    return ctrl.jvja, [(qs[k], XD[k], case.out) for k in range(K1)]


def dynamics_rows(case: Case) -> dict[str, Row]:
    """One sample of a torque-level run (control law + ABA step) at the pool's configurations.

    Empty for an arm without usable inertias (the synthetic chains carry none).
    """
    from fault_tolerance.errors import DynamicsUnavailable
    from fault_tolerance.model.dynamics import ArmDynamics
    from fault_tolerance.simulation.torque import DynamicsModel, _Arm, control_step

    try:
        dyn = ArmDynamics(case.arm)
    except DynamicsUnavailable:
        return {}
    model, n = DynamicsModel(), case.arm.n
    st = _Arm(q=case.qs[0].copy(), qd=np.zeros(n), keep=np.arange(n))
    ff = np.zeros(n)

    def sample(q, xd, out, st=st):
        """From (q, q̇ = 0.1 ẋ-sized rates): τ, saturation, one step of 1 ms."""
        st.q, st.qd = q, out
        control_step(dyn, st, model, q, out, ff, None, 1e-3)

    v = np.full(n, 0.1)
    return {"dyn_sample": (sample, [(q, xd, v) for q, xd in case.qx])}


def reference_rows(case: Case) -> dict[str, Row]:
    """The plain planner (``ft.resolve``, ``ft.rcn``), the explicit route and quadprog."""
    from fault_tolerance.resolution.api import resolve
    from fault_tolerance.resolution.indices import rcn
    from fault_tolerance.resolution.jvja import jvja_explicit

    arm, ctrl, sc, qx = case.arm, case.ctrl, case.sc, case.qx
    rows: dict[str, Row] = {
        "lnva_resolve": (lambda q, xd: resolve("lnva", arm.jacobian(q), xd), qx),
        "jvja_resolve": (lambda q, xd: resolve("jvja", arm.jacobian(q), xd, lockable=sc), qx),
        "rcn_resolve": (lambda q: rcn(arm.jacobian(q), sc), [(q,) for q in case.qs]),
        "jvja_explicit": (lambda q, xd: jvja_explicit(ctrl.jacobian(q), xd, sc), qx),
    }
    if installed("quadprog"):
        import quadprog

        rows["jvja_qp"] = (lambda q, xd: jvja_qp(ctrl.jacobian(q), xd, sc), qx)
        qp_inputs = []
        for q, xd in qx:
            J = ctrl.jacobian(q).copy()
            g = sc.weights @ post_failure_rates_explicit(J, xd, sc)
            qp_inputs.append((sc.weights.sum() * np.eye(arm.n), g, J.T.copy(), xd, arm.m))
        rows["qp_solve_only"] = (quadprog.solve_qp, qp_inputs)
    return rows


def slow_rows(case: Case) -> dict[str, Row]:
    """The slowest routes (timed with a tenth of the calls): MDA by the planner, SLSQP."""
    from fault_tolerance.resolution.api import resolve

    arm, ctrl, sc, qx = case.arm, case.ctrl, case.sc, case.qx

    def mda_resolve(q, xd):
        return resolve("mda", arm.jacobian(q), xd, lockable=sc, arm=arm, q=q)

    rows: dict[str, Row] = {"mda_resolve": (mda_resolve, qx)}
    if installed("scipy"):
        rows["jvja_slsqp"] = (lambda q, xd: jvja_slsqp(ctrl.jacobian(q), xd, sc), qx)
    return rows


#: ``(label, builder, divisor)``, timed in this order; a group's rows get ``--steps // divisor``
#: calls (at least 5) after ``--warmup // divisor`` (at least 2) warm-up calls.
def _limits_rows(case: Case) -> dict[str, Row]:
    from fault_tolerance.bench.limits_rows import limits_rows

    return limits_rows(case)


def _scaled_rows(case: Case) -> dict[str, Row]:
    from fault_tolerance.bench.scaled_rows import scaled_rows

    return scaled_rows(case)


def _fast_group(case: Case) -> dict[str, Row]:
    """The fast path, the floor, the simulated and the dynamics sample: side by side (ratios)."""
    return {**fast_rows(case), **floor_rows(case), **simulated_rows(case), **dynamics_rows(case)}


GROUPS: list[tuple[str, Callable[[Case], dict[str, Row]], int]] = [
    ("fast path, floor, simulated sample", _fast_group, 1),
    ("joint limits", _limits_rows, 1),
    ("reference routes", reference_rows, 1),
    ("slow routes", slow_rows, 10),
    (
        "task scaled",
        _scaled_rows,
        20,
    ),  # up to a millisecond a call (pink, quadprog) on a long chain
]


def deviations(case: Case, rows: dict[str, Row]) -> dict[str, float]:
    """How far each JVJA route is from the fast path over the pool, relative to the rates' size.

    (A fast wrong answer is no answer.)
    """
    ctrl, qx = case.ctrl, case.qx
    ref = [ctrl.jvja(q, xd).copy() for q, xd in qx]
    names: tuple[str, ...] = ("jvja_resolve", "jvja_explicit", "jvja_qp", "jvja_slsqp")
    names += tuple(
        k for k in rows if k.startswith("jvja_") and k not in names and "bounded" not in k
    )
    out = {}
    for name in names:
        if name not in rows or name in ("jvja", "jvja_multi"):
            continue
        fn, args = rows[name]
        got = [np.array(fn(*a[:2]), dtype=float) for a in args]
        out[name] = float(
            max(
                np.abs(g - r).max() / max(1.0, np.abs(r).max())
                for g, r in zip(got, ref, strict=True)
            )
        )
    ctrl.fallbacks = 0
    return out


def bench_arm(
    key: str, steps: int, warmup: int, backend: str = "auto", progress: Callable | None = None
) -> dict:
    """Time every row for one benchmark arm (a key of :data:`ARMS`)."""
    case = make_case(key, backend)
    built = [(label, build(case), div) for label, build, div in GROUPS]
    every = {name: row for _, rows, _ in built for name, row in rows.items()}
    deviation = deviations(case, every)
    samples: dict[str, np.ndarray] = {}
    for label, rows, div in built:
        n_steps = steps if div == 1 else max(steps // div, 5)
        n_warm = warmup if div == 1 else max(warmup // div, 2)
        if progress:
            progress(f"{key}: {label} ({len(rows)} rows x {n_steps} calls)")
        samples.update(time_rows(rows, n_steps, n_warm))
    arm, sc = case.arm, case.sc
    return {
        "robot": case.spec["robot"],
        "task": list(arm.task),
        "n": arm.n,
        "m": arm.m,
        "r": arm.redundancy,
        "lockable": [list(sc.name(S)) for S in sc.sets],
        "backend": case.ctrl.backend,
        "fallbacks_during_timing": case.ctrl.fallbacks,
        "max_rel_diff_vs_jvja": deviation,
        "ops": {
            name: {**stats(ns), "description": DESCRIPTIONS.get(name, _backend_description(name))}
            for name, ns in samples.items()
        },
    }


def _backend_description(name: str) -> str:
    method, _, backend = name.partition("_")
    return f"{method.upper()} step, fast path with the {backend} backend (Jacobian included)"
