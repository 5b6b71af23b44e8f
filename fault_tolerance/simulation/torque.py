"""Torque-level runs: the planned rates tracked by computed-torque control, integrated with ABA.

A dynamics run (``simulate(..., dynamics=DynamicsModel(...))``) has two parts:

* the **plan**: the kinematic run with perfect rate tracking (any resolver, the global plan
  included, the lock and the reduced robot's rates after it), giving ``q_ref[k]`` and the rates
  ``v[k]`` it applies over step k (``q_ref[k+1] = q_ref[k] + v[k] dt``);
* the **arm**: computed-torque control (D8)
  ``τ_cmd = RNEA(q, q̇, v̇_ff + K_d (v[k−1] − q̇) + K_p (q_ref[k] − q))``, ``v̇_ff = (v[k] − v[k−1])/dt``
  (zero at the lock's sample, where the plan's rates jump: the PD closes that gap), saturated at the effort limits, held over the step, integrated by semi-implicit Euler with ABA
  (``q̇ ← q̇ + h q̈``, ``q ← q + h q̇``, sub-steps ``h ≤ max_substep``). With the exact model, no
  saturation and one sub-step the arm reproduces the plan exactly.

At the lock the brake acts on the arm (:mod:`.brakes`): ideal (an impulse, D5) or finite (D6).
The locked joint's motor is off from then on; the surviving joints' controller tracks the plan's
reduced-robot rates, with the locked joint held in its inverse dynamics (``q̈_S = 0``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.dynamics import ArmDynamics
from fault_tolerance.model.task_errors import error_norms
from fault_tolerance.simulation.brakes import check_brake_torque, held_accelerations, ideal_brake
from fault_tolerance.simulation.run import Run

#: After the lock transient, the torque jump is measured over this long still [s].
TORQUE_WINDOW = 0.02


@dataclass(frozen=True)
class DynamicsModel:
    """How a dynamics run models the arm, its controller and the brake.

    Attributes:
        kp: Position gain of the computed-torque law [1/s²] (default: 50 rad/s natural frequency).
        kd: Velocity gain [1/s] (default: critical damping with ``kp``).
        brake_torque: Finite brake torque [N·m]; None: the ideal brake (an impulse).
        max_substep: Longest integration sub-step [s]; each control step of ``dt`` is split into
            ``ceil(dt / max_substep)`` sub-steps with the torque held.
        default_mass: Mass [kg] for moving bodies the description leaves without one (None:
            refuse them, :class:`~fault_tolerance.errors.DynamicsUnavailable`).
        gravity: Gravity on (the description's world, ``−9.81 z`` m/s²).
    """

    kp: float = 2500.0
    kd: float = 100.0
    brake_torque: float | None = None
    max_substep: float = 1e-3
    default_mass: float | None = None
    gravity: bool = True

    def __post_init__(self) -> None:
        for name, low in (("kp", ">= 0"), ("kd", ">= 0"), ("max_substep", "> 0")):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and (v > 0 or (v == 0 and low == ">= 0"))):
                raise InvalidInput(f"dynamics {name} must be finite and {low}, got {v}")
        object.__setattr__(self, "brake_torque", check_brake_torque(self.brake_torque))

    def describe(self) -> str:
        """One line for reports."""
        brake = (
            "ideal brake (impulse)"
            if self.brake_torque is None
            else f"finite brake {self.brake_torque} N·m"
        )
        return (
            f"computed-torque control (RNEA + PD, kp = {self.kp} 1/s², kd = {self.kd} 1/s), "
            f"torques saturated at the effort limits, ABA semi-implicit Euler "
            f"(sub-step <= {self.max_substep} s); {brake}"
        )


def as_model(dynamics) -> DynamicsModel | None:
    """``simulate``'s ``dynamics=`` argument: None/False, True, or a :class:`DynamicsModel`."""
    if dynamics is None or dynamics is False:
        return None
    if dynamics is True:
        return DynamicsModel()
    if isinstance(dynamics, DynamicsModel):
        return dynamics
    raise InvalidInput(
        f"dynamics must be True, False, None or a DynamicsModel, got {type(dynamics).__name__}"
    )


@dataclass
class _Arm:
    """The arm's state and what the lock did to it."""

    q: np.ndarray
    qd: np.ndarray
    keep: np.ndarray  # joints driven by their motors
    braking: bool = False  # a finite brake is decelerating the locked joint
    held: bool = False  # the locked joint is held
    impulse: float = 0.0  # [N·m·s]
    brake_time: float = 0.0  # [s]
    stop_k: int | None = None  # the first sample with the locked joint held
    energy_before: float | None = None


def track(arm, plan: Run, model: DynamicsModel) -> Run:
    """The dynamics run that tracks ``plan`` (a kinematic run with perfect rate tracking)."""
    dyn = ArmDynamics(arm, default_mass=model.default_mass, gravity=model.gravity)
    lock = plan.meta.get("lock")
    col = None if lock is None else int(lock["index"])
    k_lock = None if lock is None else int(np.searchsorted(plan.t, lock["time"] - 1e-12))
    dt = float(plan.meta["dt"])
    subs = max(1, int(np.ceil(dt / model.max_substep - 1e-9)))
    K1, n = plan.q.shape
    st = _Arm(q=plan.q[0].copy(), qd=plan.qd[0].copy(), keep=np.arange(n))
    Q, QD, TAU, CMD = (np.zeros((K1, n)) for _ in range(4))
    for k in range(K1):
        if k == k_lock and col is not None:
            _lock(dyn, st, col, model)
        if st.held and st.stop_k is None:
            st.stop_k = k
        v_prev = plan.qd[max(k - 1, 0)]
        off = col if col is not None and k_lock is not None and k >= k_lock else None
        # the plan's rates jump at the lock: no acceleration there, the PD closes the gap
        ff = np.zeros(n) if k == k_lock else (plan.qd[k] - v_prev) / dt
        Q[k], QD[k] = st.q, st.qd
        TAU[k], CMD[k] = control_step(dyn, st, model, plan.q[k], v_prev, ff, off, dt, subs)
    return _run(arm, plan, model, dyn, st, (Q, QD, TAU, CMD), k_lock, col)


# Eqn. (D8)
def control_step(dyn, st: _Arm, model, q_ref, v_prev, ff, off, dt: float, subs: int = 1):
    """One sample of the arm: the computed-torque law, saturation, ``subs`` ABA sub-steps.

    ``off``: the locked joint (its motor off, held in the inverse dynamics) or None. Returns
    ``(τ, τ_cmd)`` [N·m]; ``st`` moves on by ``dt``.
    """
    a = ff + model.kd * (v_prev - st.qd) + model.kp * (q_ref - st.q)
    if off is not None:
        a[off] = 0.0  # the locked joint's motor is off; it is held (or braked)
    cmd = dyn.inverse(st.q, st.qd, a)
    if off is not None:
        cmd[off] = 0.0
    tau = np.clip(cmd, -dyn.effort, dyn.effort)
    for _ in range(subs):
        _substep(dyn, st, tau, off, model, dt / subs)
    return tau, cmd


def _lock(dyn: ArmDynamics, st: _Arm, col: int, model: DynamicsModel) -> None:
    """The brake engages: an impulse (ideal) or a deceleration to come (finite)."""
    st.energy_before = dyn.kinetic_energy(st.q, st.qd)
    st.keep = np.array([j for j in range(len(st.q)) if j != col])
    if model.brake_torque is None:
        out = ideal_brake(dyn.mass_matrix(st.q), st.qd, [col])
        st.qd = out.qd
        st.impulse = float(abs(out.impulse[0]))
        st.held = True
    elif st.qd[col] == 0.0:
        st.held = True
    else:
        st.braking = True


def _substep(dyn: ArmDynamics, st: _Arm, tau: np.ndarray, col, model: DynamicsModel, h: float):
    """One semi-implicit Euler sub-step of length ``h`` [s]: ``q̇ += h q̈``, ``q += h q̇``."""
    if st.held:
        qdd = held_accelerations(dyn.mass_matrix(st.q), dyn.bias(st.q, st.qd), tau, st.keep)
    elif st.braking:
        brake = float(model.brake_torque or 0.0)  # [N·m]; braking only with a finite brake
        full = tau.copy()
        full[col] = -brake * np.sign(st.qd[col])
        qdd = dyn.forward(st.q, st.qd, full)
        new = st.qd[col] + h * qdd[col]
        if new * st.qd[col] <= 0.0:  # it stops within this sub-step: held from here on
            frac = abs(st.qd[col]) / max(abs(h * qdd[col]), 1e-300)
            st.brake_time += frac * h
            st.impulse += brake * frac * h
            st.qd[col] = 0.0
            st.braking, st.held = False, True
            qdd = held_accelerations(dyn.mass_matrix(st.q), dyn.bias(st.q, st.qd), tau, st.keep)
        else:
            st.brake_time += h
            st.impulse += brake * h
    else:
        qdd = dyn.forward(st.q, st.qd, tau)
    st.qd = st.qd + h * qdd
    if st.held:
        st.qd[col] = 0.0
    st.q = st.q + h * st.qd


def _lock_figures(plan: Run, st: _Arm, dyn, arrays, k_lock: int, col: int) -> dict:
    """Torque jump, impulse and kinetic-energy jump of the lock transient (docs/dynamics.md)."""
    Q, QD, TAU, _ = arrays
    K1 = len(plan.t)
    stop = K1 - 1 if st.stop_k is None else st.stop_k
    end = min(K1 - 1, stop + int(round(TORQUE_WINDOW / float(plan.meta["dt"]))))
    before = TAU[max(k_lock - 1, 0)]
    keep = st.keep
    jump = np.abs(TAU[k_lock : end + 1][:, keep] - before[keep]).max() if len(keep) else 0.0
    energy_after = dyn.kinetic_energy(Q[stop], QD[stop]) if st.stop_k is not None else None
    if st.stop_k is not None and st.stop_k == k_lock:  # the ideal brake: right after the impulse
        energy_after = dyn.kinetic_energy(Q[k_lock], QD[k_lock])
    return {
        "torque_jump_max": float(jump),
        "impulse": float(st.impulse),
        "kinetic_energy_before": st.energy_before,
        "kinetic_energy_jump": None if energy_after is None else energy_after - st.energy_before,
        "brake_time": st.brake_time,
        "stopped": st.stop_k is not None,
        "window": [float(plan.t[k_lock]), float(plan.t[end])],
    }


def _run(arm, plan: Run, model, dyn, st: _Arm, arrays, k_lock, col) -> Run:
    """The :class:`Run` of the arm: its own q, q̇, task error and torques; the plan's indices."""
    Q, QD, TAU, CMD = arrays
    X = np.array([arm.fk(q) for q in Q])
    err = np.array([arm.task_error(xd, q) for xd, q in zip(plan.x_des, Q, strict=True)])
    error, ori = error_norms(arm.task, err)
    meta = dict(plan.meta)
    meta["dynamics"] = {
        "model": model.describe(),
        "kp": model.kp,
        "kd": model.kd,
        "brake": "ideal" if model.brake_torque is None else "finite",
        "brake_torque": model.brake_torque,
        "substeps": max(1, int(np.ceil(float(meta["dt"]) / model.max_substep - 1e-9))),
        "gravity": model.gravity,
        "default_masses": dyn.default_masses,
        "effort": [float(e) if np.isfinite(e) else None for e in dyn.effort],
        "lock": None if k_lock is None else _lock_figures(plan, st, dyn, arrays, k_lock, col),
    }
    meta["servo"] = model.describe()
    return Run(
        t=plan.t, q=Q, qd=QD, x=X, x_des=plan.x_des, error=error, jvj=plan.jvj,
        jvj_parts=plan.jvj_parts, rcn=plan.rcn, K=plan.K, sigma_min=plan.sigma_min,
        flags=plan.flags, meta=meta, qd_cmd=plan.qd.copy(), arm_record=plan.arm_record,
        orientation_error=ori, tau=TAU, tau_cmd=CMD,
    )  # fmt: skip
