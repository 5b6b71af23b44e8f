"""The robots we know by name: the shipped catalog (``robots/``) and example-robot-data presets."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

from fault_tolerance.errors import FaultToleranceError

#: Arms of example-robot-data with the defaults we give them: tip frame, task, active joints.
EXAMPLE_ROBOTS: dict[str, dict] = {
    "panda": {
        "tip": "panda_hand_tcp",
        "task": "pose",
        "joints": [f"panda_joint{i}" for i in range(1, 8)],
        "description": "Franka Panda (example-robot-data), fingers fixed",
    },
    "ur5": {
        "tip": "tool0",
        "task": "position",
        "joints": None,
        "description": "Universal Robots UR5 (example-robot-data)",
    },
    "xarm7": {
        "tip": "link_eef",
        "task": "pose",
        "joints": None,
        "description": "UFactory xArm7 (example-robot-data)",
    },
}


def robots_dir() -> Path:
    """The folder of the shipped robots, in every layout the package runs from.

    Installed (wheel or editable), the robots are the package data ``fault_tolerance.robots``.
    Run from the root of a clone after a non-editable ``pip install .``, the clone's own
    ``fault_tolerance/`` folder shadows the installed package and has no ``robots`` subpackage;
    the robots are then the clone's ``robots/`` folder beside it.
    """
    try:
        found = Path(str(resources.files("fault_tolerance.robots")))
        if (found / "catalog.json").is_file():
            return found
    except ModuleNotFoundError:
        pass
    here = Path(__file__).resolve().parents[1]  # the fault_tolerance/ folder
    for folder in (here / "robots", here.parent / "robots"):
        if (folder / "catalog.json").is_file():
            return folder
    raise FaultToleranceError(
        f"the shipped robots (robots/catalog.json) are missing: neither the package data "
        f"'fault_tolerance.robots' nor {here.parent / 'robots'} exists; reinstall the package "
        "(pip install .)"
    )


def catalog() -> dict[str, dict]:
    """The shipped robots (``robots/catalog.json``): URDF file, tip, task, lockable joints."""
    return json.loads((robots_dir() / "catalog.json").read_text())


def robot_path(filename: str) -> Path:
    """Path of a file shipped in ``robots/`` (from a wheel, an editable install or a clone)."""
    return robots_dir() / filename


def preset_names() -> list[str]:
    """The arms with a preset: the shipped robots, then the example-robot-data arms we configure."""
    return list(catalog()) + list(EXAMPLE_ROBOTS)


def example_robot_names() -> list[str]:
    """Names example-robot-data can load (empty if its loaders are missing)."""
    try:
        from example_robot_data.robots_loader import ROBOTS
    except ImportError:
        return []
    return sorted(ROBOTS)
