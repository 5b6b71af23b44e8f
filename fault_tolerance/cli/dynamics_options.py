"""``--dynamics`` and its options (``simulate``, ``lock``), and the torque table they print."""

from __future__ import annotations

import argparse

from fault_tolerance.errors import InvalidInput


def add_dynamics_options(s: argparse.ArgumentParser, lock: bool = False) -> None:
    """``--dynamics``, ``--kp``, ``--kd``, ``--default-mass`` (and ``--brake-torque`` for lock)."""
    g = s.add_argument_group("dynamics (docs/dynamics.md)")
    g.add_argument(
        "--dynamics",
        action="store_true",
        help="torque-level run: the planned rates tracked by computed torque with the arm's "
        "inertias, torques saturated at the effort limits"
        + ("; the lock as an ideal brake and as a finite one" if lock else ""),
    )
    g.add_argument("--kp", type=float, default=2500.0, help="position gain [1/s²] (default 2500)")
    g.add_argument("--kd", type=float, default=100.0, help="velocity gain [1/s] (default 100)")
    g.add_argument(
        "--default-mass",
        type=float,
        default=None,
        help="mass [kg] for links without <inertial> (default: such a description is refused)",
    )
    if lock:
        g.add_argument(
            "--brake-torque",
            type=float,
            default=None,
            help="finite brake torque [N·m] (default: the locked joint's effort limit)",
        )


def check_dynamics_args(args) -> None:
    """Dynamics options without ``--dynamics`` are refused (they would do nothing)."""
    if args.dynamics:
        return
    given = [
        flag
        for flag, value, default in (
            ("--kp", args.kp, 2500.0),
            ("--kd", args.kd, 100.0),
            ("--default-mass", args.default_mass, None),
            ("--brake-torque", getattr(args, "brake_torque", None), None),
        )
        if value != default
    ]
    if given:
        raise InvalidInput(f"{', '.join(given)} apply to torque-level runs only: add --dynamics")


def dynamics_model(args, brake_torque: float | None = None):
    """The :class:`~fault_tolerance.simulation.torque.DynamicsModel` of the options."""
    from fault_tolerance.simulation.torque import DynamicsModel

    return DynamicsModel(
        kp=args.kp, kd=args.kd, brake_torque=brake_torque, default_mass=args.default_mass
    )


def print_torque_table(rows: dict) -> None:
    """One line per (algorithm, brake): jumps, torque, impulse, energy, path error."""
    print(
        f"{'algorithm':13} {'brake':14} {'jump (rad/s)²':>14} {'τ jump [N·m]':>13} "
        f"{'peak |τ|/τmax':>14} {'impulse [N·m·s]':>16} {'ΔT [J]':>10} {'path err [mm]':>14}"
    )
    for (alg, brake), s in rows.items():
        ratio = s.get("torque_peak_ratio")
        energy = s.get("kinetic_energy_jump")
        print(
            f"{alg:13} {brake:14} {s.get('jump_at_lock') or 0.0:14.4g} "
            f"{s['torque_jump_max']:13.4g} {ratio if ratio is not None else float('nan'):14.3f} "
            f"{s['lock_impulse']:16.4g} {energy if energy is not None else float('nan'):10.4g} "
            f"{1e3 * s['path_error_peak_after_lock']:14.3f}"
        )
