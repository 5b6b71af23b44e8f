"""Which preset arms suit a command: the list an unknown ``--robot`` name is answered with.

``simulate``, ``lock`` and ``inspect`` take every preset arm (all are redundant for their task);
``workspace`` needs a planar or position task (2 or 3 linear rows) with redundancy; ``design``
needs a planar 3R. The arms are loaded to check (only on this error path).
"""

from __future__ import annotations

from fault_tolerance.errors import FaultToleranceError, RobotNotFound


def _workspace(arm) -> bool:
    rows = list(arm.task)
    return arm.redundancy >= 1 and len(rows) in (2, 3) and not any(r.startswith("r") for r in rows)


def _design(arm) -> bool:
    from fault_tolerance.model.planar import planar_chain

    return arm.n == 3 and planar_chain(arm) is not None


CHECKS = {"workspace": _workspace, "design": _design}


def suited_arms(command: str | None) -> list[str]:
    """The preset arms (``fault-tolerance robots``) that ``command`` can run as they load."""
    from fault_tolerance.model.catalog import preset_names
    from fault_tolerance.model.loading import load_arm

    check = CHECKS.get(command or "")
    if check is None:
        return preset_names()
    suited = []
    for name in preset_names():
        try:
            if check(load_arm(name)):
                suited.append(name)
        except FaultToleranceError:  # pragma: no cover - depends on the installed data
            continue
    return suited


def robot_not_found(err: RobotNotFound, command: str | None) -> RobotNotFound:
    """``err`` again, listing the arms that suit ``command``."""
    return RobotNotFound(err.name, err.known, suits=suited_arms(command), command=command)
