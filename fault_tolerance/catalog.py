"""The robots we know by name: the shipped catalog (``robots/``) and example-robot-data presets."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

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


def catalog() -> dict[str, dict]:
    """The shipped robots (``robots/catalog.json``): URDF file, tip, task, lockable joints."""
    text = resources.files("fault_tolerance.robots").joinpath("catalog.json").read_text()
    return json.loads(text)


def robot_path(filename: str) -> Path:
    """Path of a file shipped in ``robots/`` (works from a checkout and from a wheel)."""
    return Path(str(resources.files("fault_tolerance.robots").joinpath(filename)))


def example_robot_names() -> list[str]:
    """Names example-robot-data can load (empty if its loaders are missing)."""
    try:
        from example_robot_data.robots_loader import ROBOTS
    except ImportError:
        return []
    return sorted(ROBOTS)
