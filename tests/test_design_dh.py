"""DH designs: parameters, candidates, the search (planted optimum, scans, resume, workers), the CLI."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from fault_tolerance.analysis.design.dh import (
    DHTask,
    baseline_u,
    candidate_table,
    design_spec,
    dh_design,
    evaluate_table,
    parse_params,
)
from fault_tolerance.analysis.design.search_core import check_budget, global_search
from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.dh import TEMPLATES

FIG6 = DHTask((0.09, 0.21, 0.27), 0.075)
LOCK = ["joint1", "joint2", "joint3"]
BASE = TEMPLATES["spatial_4r"]


def test_parameters_parse_and_refuse():
    """FIELDJOINT:LO:HI and FIELDJOINT:{A|B} with pi; a bad field, order, repeat or number raises."""
    p = parse_params("d3:0.2:0.6, alpha2:{0|pi/2|-pi/2}")
    assert [q.name for q in p] == ["d3", "alpha2"]
    assert p[1].choices == (0.0, math.pi / 2, -math.pi / 2)
    assert p[0].value(0.5) == pytest.approx(0.4) and p[1].value(0.99) == -math.pi / 2
    for bad, match in [
        ("x3:0:1", "field"),
        ("d3:0.6:0.2", "lo < hi"),
        ("d3:0:1,d3:0:2", "twice"),
        ("d3:a:b", "not a number"),
        ("d3", "FIELDJOINT"),
        ("", "no DH parameter"),
    ]:
        with pytest.raises(InvalidInput, match=match):
            parse_params(bad)


def test_candidates_keep_the_total_length():
    """With a fixed total, the sum of |a|, |d| and the tool offset is the base arm's (1.3 m)."""
    p = parse_params("d3:0.2:0.6,a4:0.1:0.5")
    t = candidate_table(BASE, p, [1.0, 0.0], total_length=1.3)
    assert sum(abs(j.a) + abs(j.d) for j in t.joints) == pytest.approx(1.3)
    assert t.joints[2].d / t.joints[3].a == pytest.approx(0.6 / 0.1)
    np.testing.assert_allclose(baseline_u(BASE, p), [0.5, 0.5])
    assert baseline_u(BASE, parse_params("d3:0.5:0.6")) is None  # 0.4 is outside


def test_the_search_finds_a_planted_optimum_and_repeats_itself():
    """A synthetic objective with its minimum at a known point is found; the same seed gives the
    same candidates in the same order; budgets past the limit are refused up front."""

    def f(U, tag):
        return np.sum((U - [0.2, 0.7, 0.55]) ** 2, axis=1) + 0.1 * (U[:, 0] > 0.9)

    a = global_search(f, dims=3, seed=4, popsize=8, generations=25, pattern_rounds=8)
    b = global_search(f, dims=3, seed=4, popsize=8, generations=25, pattern_rounds=8)
    np.testing.assert_allclose(a.u, [0.2, 0.7, 0.55], atol=2e-3)
    assert np.array_equal(a.evaluated, b.evaluated) and np.array_equal(a.scores, b.scores)
    refused = global_search(
        lambda U, tag: np.where(U[:, 0] < 0.5, np.inf, U[:, 0]), dims=1, seed=0, popsize=5,
        generations=5, pattern_rounds=3,
    )  # fmt: skip
    assert refused.u[0] == pytest.approx(0.5, abs=0.02)  # refused candidates are only refused
    with pytest.raises(InvalidInput, match="limit"):
        check_budget(4, 1000, 1000, 0)


def test_a_refused_candidate_is_a_record_not_an_exception():
    """An arm that cannot reach the task is refused (feasible False, with the reason)."""
    tiny = candidate_table(BASE, parse_params("d3:0.2:0.6"), [0.0], total_length=0.2)
    rec = evaluate_table(tiny, FIG6, LOCK)
    assert rec["feasible"] is False and rec["reason"]


@pytest.mark.slow
def test_the_search_is_within_one_percent_of_a_scan(tmp_path):
    """On the 2-parameter 4R family (upper arm d3, forearm a4, total length fixed) the search's
    mean jump is within 1 % of the best of a 5 x 5 scan at the same time step."""
    params = parse_params("d3:0.25:0.55,a4:0.15:0.45")
    spec = design_spec(BASE, params, FIG6, LOCK, total_length=1.3, search_dt=1e-2)
    from fault_tolerance.analysis.design.dh import evaluate_candidate

    grid = np.linspace(0, 1, 5)
    scan = min(evaluate_candidate(spec, [u, v])["score"] for u in grid for v in grid)
    d = dh_design(spec, popsize=4, generations=3, pattern_rounds=3, folder=tmp_path / "s")
    best = float(np.nanmin(np.where(d.evaluated["feasible"], d.evaluated["score"], np.nan)))
    assert math.isfinite(scan) and best <= 1.01 * scan
    assert d.record["mean_jvj"] <= d.record["baseline"]["mean_jvj"] * 1.001
    assert d.record["rcn_max"] <= spec["rcn_max"]


@pytest.mark.slow
def test_resume_and_workers_give_the_same_design(tmp_path):
    """Interrupted after its first round, a rerun on the same folder reuses the chunks and gives
    the same design; a Dask cluster of 2 workers gives the same design as the serial run."""
    spec = design_spec(BASE, parse_params("d3:0.3:0.5"), FIG6, LOCK, total_length=1.3)
    opts = dict(popsize=4, generations=1, pattern_rounds=1)
    serial = dh_design(spec, **opts, folder=tmp_path / "serial")
    import fault_tolerance.analysis.sweep as sweep

    calls = {"n": 0}
    real = sweep.run

    def interrupted(*a, **k):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(*a, **k)

    sweep.run = interrupted
    try:
        with pytest.raises(KeyboardInterrupt):
            dh_design(spec, **opts, folder=tmp_path / "resumed")
    finally:
        sweep.run = real
    resumed = dh_design(spec, **opts, folder=tmp_path / "resumed")
    assert resumed.record["parameters"] == serial.record["parameters"]
    dask = dh_design(spec, **opts, folder=tmp_path / "dask", workers=2)
    assert dask.record["parameters"] == serial.record["parameters"]
    np.testing.assert_array_equal(dask.evaluated["score"], serial.evaluated["score"])


@pytest.mark.slow
def test_cli_design_dh_and_its_urdf_reproduce(tmp_path):
    """`design --vary dh` writes design.json, design.urdf, design.png and replay.html; `simulate`
    of design.urdf from the reported start gives the reported mean jump and largest k_S."""
    out = tmp_path / "d"
    cmd = [sys.executable, "-m", "fault_tolerance", "design", "--vary", "dh", "--params",
           "d3:0.3:0.5", "--popsize", "4", "--generations", "1", "--rounds", "1",
           "--no-progress", "--out", str(out)]  # fmt: skip
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
    assert p.returncode == 0, p.stderr
    assert {"design.json", "design.urdf", "design.png", "replay.html"} <= {
        f.name for f in out.iterdir()
    }
    rec = json.loads((out / "design.json").read_text())
    assert rec["kind"] == "dh" and rec["pareto"] and rec["rcn_max"] <= 100
    q0 = ",".join(f"{v:.17g}" for v in rec["q0"])
    sim = [sys.executable, "-m", "fault_tolerance", "simulate", "--description", str(out / "design.urdf"),
           "--tip", "tool", "--task", "position", "--lockable", "joint1,joint2,joint3",
           "--q0", q0, "--radius", "0.075", "--rows", "y,z", "--algorithms", "jvja",
           "--no-limits", "--no-progress", "--out", str(tmp_path / "check")]  # fmt: skip
    p = subprocess.run(sim, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr
    got = json.loads((tmp_path / "check" / "jvja" / "summary.json").read_text())["summary"]
    assert got["jvj_mean"] == pytest.approx(rec["mean_jvj"], rel=1e-6)
    assert got["rcn_max"] == pytest.approx(rec["K_max"], rel=1e-6)  # summary.json: max K(t)


def test_bad_cli_input_exits_2(tmp_path):
    """--vary dh with --robot, an unknown template or bad params: exit 2, one line."""
    for extra in (["--robot", "planar_3r"], ["--dh", "nope"], ["--params", "q3:0:1"]):
        cmd = [sys.executable, "-m", "fault_tolerance", "design", "--vary", "dh", *extra,
               "--out", str(tmp_path / "x")]  # fmt: skip
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert p.returncode == 2, (extra, p.stderr)
        assert len(p.stderr.strip().splitlines()) == 1, p.stderr


def test_ftw_volume_equals_the_workspace_command_on_the_exported_urdf(tmp_path):
    """A candidate's sampled failure-tolerant volume (its limits as A inside the base table's)
    equals failure_tolerant_workspace on the URDF of the physical table with those limits, and
    is positive for the narrow limits of docs/figures.md (±20° on the lockable joints)."""
    from dataclasses import replace

    import fault_tolerance as ft
    from fault_tolerance.analysis.design.dh import FTW_SETTINGS, ftw_volume
    from fault_tolerance.analysis.workspace.closed_form import failure_tolerant_workspace
    from fault_tolerance.model.dh import dh_urdf

    A = np.radians([[-20, 20], [-20, 20], [-20, 20], [-170, 170]])
    narrow = replace(
        BASE,
        joints=tuple(
            replace(j, lower=a, upper=b) for j, (a, b) in zip(BASE.joints, A, strict=True)
        ),
    )
    physical = [[j.lower, j.upper] for j in BASE.joints]
    got = ftw_volume(narrow, LOCK, FTW_SETTINGS | {"physical": physical})
    (tmp_path / "arm.urdf").write_text(dh_urdf(BASE))
    arm = ft.load_arm(tmp_path / "arm.urdf", tip="tool", task="position")
    ws = failure_tolerant_workspace(arm, A, LOCK, **FTW_SETTINGS)
    assert got == ws.size_ftw > 0
    assert ftw_volume(BASE, LOCK, FTW_SETTINGS | {"physical": physical}) == 0.0  # A = physical


@pytest.mark.slow
def test_a_volume_design_finds_failure_tolerant_limits(tmp_path):
    """--vary dh,limits with the ftw-volume objective: the base arm (A = its physical limits) has
    no failure-tolerant volume; the design's limits have one, stated with its sampling."""
    params = parse_params(",".join(f"lower{i}:-3.1416:-0.2,upper{i}:0.2:3.1416" for i in (1, 2, 3)))
    spec = design_spec(BASE, params, FIG6, LOCK, objective="ftw-volume", search_dt=2e-2)
    d = dh_design(spec, popsize=4, generations=2, pattern_rounds=1, folder=tmp_path / "v")
    rec = d.record
    assert rec["baseline"]["ftw_volume"] == 0.0 < rec["ftw_volume"]
    assert rec["settings"]["ftw"]["grid"] == 16 and "ftw_volume" in rec["units"]
    feasible = d.evaluated["feasible"].astype(bool)  # the task and the RCN requirement hold
    assert rec["ftw_volume"] >= np.nanmax(d.evaluated["ftw_volume"][feasible]) - 1e-12


def _circle_csv(path, task: DHTask, dt: float = 1e-3):
    """The task circle written as a CSV path (t, x, y, z with velocities), as a user would."""
    circle = task.path()
    t = np.arange(0.0, task.duration + dt / 2, dt)
    rows = [[s, *circle.x(s), *circle.xdot(s)] for s in t]
    np.savetxt(path, rows, delimiter=",", header="t,x,y,z,vx,vy,vz", comments="")
    return path


def test_a_csv_task_designs_like_the_circle_it_samples(tmp_path):
    """The Fig. 6 circle as a CSV path gives the circle's jump and RCN (to the sampling), and a
    circle's spec keeps its keys (its chunks are reused)."""
    from fault_tolerance.simulation.paths import load_csv

    sampled = DHTask.sampled(load_csv(_circle_csv(tmp_path / "c.csv", FIG6)))
    a = evaluate_table(BASE, FIG6, LOCK, dt=1e-2)
    b = evaluate_table(BASE, sampled, LOCK, dt=1e-2)
    assert a["feasible"] and b["feasible"]
    assert b["mean_jvj"] == pytest.approx(a["mean_jvj"], rel=1e-3)
    assert b["rcn_max"] == pytest.approx(a["rcn_max"], rel=1e-3)
    assert DHTask.from_spec(sampled.as_spec()) == sampled
    assert set(FIG6.as_spec()) == {"x0", "radius", "omega", "duration", "rows"}


def test_the_cli_takes_a_csv_task_for_dh_designs_only(tmp_path, capsys):
    """--csv with --x0 is refused, and so is --csv for a planar design (exit 2, one line)."""
    from fault_tolerance.cli import main

    csv_file = str(_circle_csv(tmp_path / "c.csv", FIG6, dt=1e-2))
    assert main(["design", "--vary", "dh", "--csv", csv_file, "--x0", "0.1,0.2,0.3",
                 "--out", str(tmp_path / "o")]) == 2  # fmt: skip
    assert "without --x0" in capsys.readouterr().err
    assert main(["design", "--robot", "planar_3r", "--csv", csv_file,
                 "--out", str(tmp_path / "p")]) == 2  # fmt: skip
    assert "--csv" in capsys.readouterr().err
