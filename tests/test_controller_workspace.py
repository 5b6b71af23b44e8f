"""The Controller owns its state: one frozen workspace, and no private attribute read from outside."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.control.controller import Controller
from fault_tolerance.control.workspace import ControllerWorkspace

PKG = Path(__file__).resolve().parents[1] / "fault_tolerance"
#: Names under which code holds a Controller.
CONTROLLER_NAMES = {"ctrl", "controller", "boxed"}


def private_reads(source: str) -> list[str]:
    """``name._x`` / ``self.name._x`` for a Controller ``name`` (dunders aside), as text."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Attribute):
            continue
        if not node.attr.startswith("_") or node.attr.startswith("__"):
            continue
        holder = node.value
        name = holder.id if isinstance(holder, ast.Name) else None
        if isinstance(holder, ast.Attribute) and isinstance(holder.value, ast.Name):
            name = holder.attr if holder.value.id == "self" else None
        if name in CONTROLLER_NAMES:
            found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


def test_the_private_read_check_can_fail():
    """The check sees ``ctrl._x``, ``controller._x`` and ``self.ctrl._x``, not ``ctrl.x``."""
    src = "a = ctrl._rows\nb = self.ctrl._fw\nc = controller._la\nd = ctrl.rows\ne = ctrl.__doc__\n"
    assert [r.split(": ")[1] for r in private_reads(src)] == [
        "ctrl._rows",
        "self.ctrl._fw",
        "controller._la",
    ]


def test_nothing_reads_a_controllers_private_attributes():
    """No module of the package, control/ included, reads ``ctrl._anything``: the workspace is public."""
    bad = {
        str(p.relative_to(PKG)): hits
        for p in sorted(PKG.rglob("*.py"))
        if (hits := private_reads(p.read_text(encoding="utf-8")))
    }
    assert bad == {}


@pytest.mark.parametrize("backend", ["numpy"])
def test_the_workspace_is_frozen_and_holds_the_state(backend):
    """Fields cannot be rebound; last_scale, last_active and the counters read the workspace."""
    arm = ft.load_arm("planar_3r")
    ctrl = Controller(arm, lockable="all", backend=backend)
    ws = ctrl.workspace
    assert isinstance(ws, ControllerWorkspace)
    with pytest.raises(dataclasses.FrozenInstanceError):
        ws.fw = np.zeros((2, arm.n))  # type: ignore[misc]
    assert ws.fw.shape == (2, arm.n) and ws.keep.shape == (ws.f, 1, arm.n)
    ws.box_state[0], ws.box_state[2:] = 0.5, [0.0, 1.0, 0.0]
    assert ctrl.last_scale == 0.5
    assert ctrl.last_active.tolist() == [False, True, False]
    ctrl.fallbacks = 3
    assert int(ws.counts[0]) == 3 and ctrl.fallbacks == 3


def test_a_singular_step_is_counted_in_the_workspace():
    """A step handed to the planner (J singular) counts in ``counts`` and in ``fallbacks``."""
    arm = ft.load_arm("planar_3r")
    ctrl = Controller(arm, lockable="all", backend="numpy", limits=False)
    q = np.zeros(arm.n)  # stretched out: J loses rank
    qd = ctrl.step(q, np.array([0.0, 0.1]))
    assert ctrl.fallbacks == 1 and int(ctrl.workspace.counts[0]) == 1
    assert np.all(np.isfinite(qd))
