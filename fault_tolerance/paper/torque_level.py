"""What the paper did not measure: the lock at torque level (REPORT.md's section of that name).

On the paper's arms (the Fig. 2 and Fig. 6 cases, the Power-Cube of Sec. V) and on the Panda
(example-robot-data's inertias), every planner runs from the same start to the same lock; one
kinematic plan per planner is tracked twice by computed torque (:mod:`fault_tolerance.simulation.torque`),
once with the ideal brake and once with a finite brake of the locked joint's effort limit. The
section compares the velocity jump with the torque jump, the peak-torque ratio, the impulse, the
kinetic-energy jump and the path error after the lock.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fault_tolerance.model.loading import load_arm
from fault_tolerance.paper.cases import CASES, EXPERIMENT
from fault_tolerance.planning.default_start import default_start
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.setup import ServoModel
from fault_tolerance.simulation.simulate import simulate
from fault_tolerance.simulation.torque import DynamicsModel, track

#: The planners compared.
PLANNERS = ("lnva", "jvja", "jvja_inertia", "mda", "global")
#: Figures of each run in the section.
FIGURES = ("jump_at_lock", "torque_jump_max", "torque_peak_ratio", "lock_impulse",
           "kinetic_energy_jump", "path_error_peak_after_lock")  # fmt: skip
#: When the joint locks [s], and how long the run goes on after it [s].
LOCK_TIME, AFTER = 0.3, 0.2
#: Task-space feedback of the runs [1/s] (as `fault-tolerance lock`).
FEEDBACK = 10.0


@dataclass(frozen=True)
class TorqueCase:
    """One arm, its start, path and the joint that locks."""

    key: str
    title: str
    robot: str
    task: str | None
    lockable: tuple[str, ...]
    joint: str

    def setup(self):
        """``(arm, path, q0)``: the paper's circle and start for its cases, a circle for the Panda."""
        arm = load_arm(self.robot, **({"task": self.task} if self.task else {}))
        T = LOCK_TIME + AFTER
        if self.key in CASES:
            path = CASES[self.key].path(T)
        elif self.key == "experiment":
            path = EXPERIMENT.path(T)
        else:
            x0 = arm.fk(arm.q_reference)
            path = CirclePath(x0, 0.05, 2 * np.pi, T, rows=(0, 1), name=self.key)
        x0 = np.asarray(path.x(0.0), dtype=float)
        q0 = default_start(arm, list(self.lockable), x0=x0, path=path).q0
        return arm, path, q0


CASES_TL = (
    TorqueCase("fig2", "planar 3R (Fig. 2)", "planar_3r", None, ("joint1", "joint2", "joint3"),
               "joint2"),
    TorqueCase("fig6", "spatial 4R (Fig. 6)", "spatial_4r", None, ("joint1", "joint2", "joint3"),
               "joint2"),
    TorqueCase("experiment", "Power-Cube 3R (Sec. V)", "powercube_3r", None, ("joint3",), "joint3"),
    TorqueCase("panda", "Panda, pose task (r = 1)", "panda", "pose",
               tuple(f"panda_joint{i}" for i in range(1, 8)), "panda_joint4"),
    TorqueCase("panda_position", "Panda, position task (r = 4)", "panda", "position",
               tuple(f"panda_joint{i}" for i in range(1, 8)), "panda_joint4"),
)  # fmt: skip


def run_case(case: TorqueCase) -> dict:
    """Every planner, both brakes, from the same start: the section's entry for one arm."""
    arm, path, q0 = case.setup()
    col = arm.joint_index(case.joint)
    brake = float(arm.model.effortLimit[col])
    models = {"ideal": DynamicsModel(), "finite": DynamicsModel(brake_torque=brake)}
    algs: dict = {}
    for alg in PLANNERS:
        plan = simulate(
            arm, path, alg, q0=q0, lockable=list(case.lockable), lock_joint=case.joint,
            lock_time=LOCK_TIME, servo=ServoModel(tau=0.0), feedback_gain=FEEDBACK,
        )  # fmt: skip
        algs[alg] = {}
        for label, model in models.items():
            s = track(arm, plan, model).summary()
            algs[alg][label] = {k: s.get(k) for k in FIGURES}
    return {
        "title": case.title,
        "robot": case.robot,
        "task": list(arm.task),
        "redundancy": arm.redundancy,
        "joint": case.joint,
        "lock_time": LOCK_TIME,
        "duration": LOCK_TIME + AFTER,
        "brake_torque": brake,
        "q0": np.asarray(q0, dtype=float).tolist(),
        "algorithms": algs,
    }


def torque_level(keys=None) -> dict:
    """The section's data: one entry per arm (all of :data:`CASES_TL` by default)."""
    return {c.key: run_case(c) for c in CASES_TL if keys is None or c.key in keys}


def _best(entry: dict, brake: str, key: str) -> set[str]:
    """The planners with the smallest ``key`` (ties within 1e-6 relative or 1e-12 absolute)."""
    values = {a: v[brake][key] for a, v in entry["algorithms"].items()}
    low = min(values.values())
    return {a for a, x in values.items() if x <= low + max(1e-6 * abs(low), 1e-12)}


def _saturated(entry: dict, brake: str) -> bool:
    return all(
        (v[brake]["torque_peak_ratio"] or 0.0) >= 1.0 - 1e-9 for v in entry["algorithms"].values()
    )


def verdicts(data: dict) -> list[str]:
    """Per arm and brake: which planners give the smallest velocity jump and torque jump."""
    out = []
    for entry in data.values():
        for brake in ("ideal", "finite"):
            v = _best(entry, brake, "jump_at_lock")
            t = _best(entry, brake, "torque_jump_max")
            same = "the same" if v & t else "**not the same**"
            note = (
                " Every planner saturates an actuator at the lock: the torque jump is set by the "
                "effort limits, not by the planner."
                if _saturated(entry, brake)
                else ""
            )
            out.append(
                f"* {entry['title']}, {brake} brake: minimum velocity jump {sorted(v)}, minimum "
                f"torque jump {sorted(t)} — {same}.{note}"
            )
    return out


def report_section(data: dict) -> str:
    """REPORT.md's section "The lock at torque level"."""
    lines = [
        "## The lock at torque level",
        "",
        "The paper measures the joint-velocity jump only. Here every planner runs from the same "
        f"start to the same lock (t = {LOCK_TIME} s, then {AFTER} s more), and its plan is "
        "tracked by computed torque (RNEA + PD, kp = 2500 1/s², kd = 100 1/s, torques saturated "
        "at the URDF effort limits, ABA semi-implicit Euler at 1 ms; docs/dynamics.md). The lock "
        "is an ideal brake (an impulse, docs/MATH.md (D5)) or a finite brake of the locked "
        "joint's effort limit (D6). Velocity jump in (rad/s)², torque jump in N·m (surviving "
        "joints), peak |τ|/τ_max, impulse in N·m·s, ΔT in J, path error after the lock in mm.",
        "",
    ]
    for entry in data.values():
        lines += _table(entry)
    lines += ["### Does the minimum velocity jump mean the minimum torque jump?", "",
              *verdicts(data), ""]  # fmt: skip
    lines += [
        "The velocity jump here is the one joint that locks; JVJA minimises the square sum over "
        "every lockable joint (eq. (9)), so for one particular joint at one instant another "
        "planner can jump less (the spatial 4R's joint 2).",
        "",
        "The inertia-weighted JVJA (`jvja_inertia`, (D3)) gives JVJA's rates wherever the arm has "
        "one degree of redundancy (D4): the planar 3R, the spatial 4R, the Power-Cube and the "
        "Panda with a pose task, in the unconstrained formulation (checked: without joint limits "
        "the two Panda pose runs agree to 1e-12). Under joint limits (these runs) JVJA measures "
        "each reduced robot's response inside the rate box (docs/MATH.md (L4)-(L5)) and "
        "`jvja_inertia`'s bounded variant does not (it bounds only its own rates), so the two "
        "part on the Panda pose run where a reduced robot meets its box. Beyond r = 1 they "
        "differ by design (the Panda with a position task, r = 4).",
        "",
    ]
    return "\n".join(lines)


def _table(entry: dict) -> list[str]:
    out = [
        f"### {entry['title']}: {entry['joint']} locks (finite brake {entry['brake_torque']:g} N·m)",
        "",
        "| planner | brake | velocity jump | torque jump | peak τ ratio | impulse | ΔT | path error |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for alg, by_brake in entry["algorithms"].items():
        for brake, s in by_brake.items():
            ratio = s["torque_peak_ratio"]
            energy = s["kinetic_energy_jump"]
            out.append(
                f"| {alg} | {brake} | {s['jump_at_lock']:.4g} | {s['torque_jump_max']:.4g} | "
                f"{'n/a' if ratio is None else f'{ratio:.3f}'} | {s['lock_impulse']:.4g} | "
                f"{'n/a' if energy is None else f'{energy:.3g}'} | "
                f"{1e3 * s['path_error_peak_after_lock']:.3f} |"
            )
    return out + [""]
