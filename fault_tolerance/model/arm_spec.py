"""What a worker needs to rebuild an arm, and a per-process cache of the arms it built."""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path


def robot_spec(arm) -> dict:
    """What a worker needs to rebuild ``arm`` (source, tip, task, joints, package dirs)."""
    spec = {
        "source": arm.source or arm.name,
        "tip": arm.tip,
        "task": list(arm.task),
        "joints": list(arm.joint_names),
        "package_dirs": list(arm.package_dirs),
    }
    path = Path(spec["source"])
    if path.is_file():  # an edited URDF is a new spec (its chunks are not reused)
        spec["sha256"] = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
    return spec


@functools.lru_cache(maxsize=8)
def _arm_cached(text: str):
    from fault_tolerance.model.loading import load_arm

    s = json.loads(text)
    return load_arm(
        s["source"],
        tip=s["tip"],
        task=s["task"],
        joints=s["joints"],
        package_dirs=s["package_dirs"] or None,
    )


def arm_of(spec: dict):
    """The arm of a spec's robot entry, loaded once per process."""
    return _arm_cached(json.dumps(spec["robot"], sort_keys=True))
