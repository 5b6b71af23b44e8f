"""Fair comparisons: one start per table, a named winner, honest global plans."""

from __future__ import annotations

import json
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.simulation.compare import compare_runs
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.simulate import simulate

X0_4R = "-0.21,0.20,0.35"


def _cli(*args, timeout=900):
    return subprocess.run(
        [sys.executable, "-m", "fault_tolerance", *args, "--no-progress"],
        capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip


def _fake(q0, jvj):
    return SimpleNamespace(q=np.array([q0]), jvj=np.asarray(jvj, dtype=float))


def test_compare_runs_labels_starts_and_names_winners():
    """Same start: one line says so; different starts: labelled; ties on λ are all named."""
    same = compare_runs({"lnva": _fake([0, 1], [1, 3]), "jvja": _fake([0, 1], [1, 2])})
    assert same.same_start and "every method from the same q0" in same.lines()[0]
    assert same.mean_winners == (("jvja",), 1.5) and same.max_winners == (("jvja",), 2.0)
    tie = compare_runs({"a": _fake([0.0], [2, 2]), "b": _fake([0.0], [2, 2])})
    assert tie.mean_winners[0] == ("a", "b") and "λ mean a=b" in tie.lines()[-1]
    diff = compare_runs({"lnva": _fake([0, 1], [1, 3]), "global": _fake([0, 1.1], [0.5, 1])})
    assert not diff.same_start and diff.start_of == {"lnva": "A", "global": "B"}
    assert "NOT the same" in diff.lines()[0] and "(from different starts)" in diff.lines()[-1]
    with pytest.raises(ft.InvalidInput):
        compare_runs({})


@pytest.fixture(scope="module")
def four_r(tmp_path_factory):
    out = tmp_path_factory.mktemp("fair") / "run"
    p = _cli("simulate", "--robot", "spatial_4r", f"--x0={X0_4R}", "--algorithms",
             "lnva,jvja,global", "--duration", "0.3", "--out", str(out))  # fmt: skip
    assert p.returncode == 0, p.stderr
    return p.stdout, out


def test_simulate_table_is_from_one_start_and_names_the_winner(four_r):
    """lnva, jvja and global start from one q0 by default; the table and comparison.json say so."""
    stdout, out = four_r
    assert "start: every method from the same q0" in stdout
    assert "winner: λ mean" in stdout and "λ max" in stdout
    cmp = json.loads((out / "comparison.json").read_text())
    assert cmp["same_start"] and set(cmp["start_of"].values()) == {"A"}
    means = {
        a: json.loads((out / a / "summary.json").read_text())["summary"]["jvj_mean"]
        for a in cmp["start_of"]
    }
    assert means["global"] <= min(means["lnva"], means["jvja"]) * (1 + 1e-12)
    assert cmp["winner_jvj_mean"]["value"] == pytest.approx(min(means.values()), rel=1e-12)
    starts = {a: ft.Run.load(out / a).q[0] for a in ("lnva", "jvja", "global")}
    np.testing.assert_array_equal(starts["global"], starts["lnva"])


def test_free_global_start_is_asked_for_and_said():
    """--global-start free gives global its own start, and the table says the starts differ."""
    p = _cli("simulate", "--robot", "spatial_4r", f"--x0={X0_4R}", "--algorithms",
             "lnva,global", "--duration", "0.3", "--global-start", "free")  # fmt: skip
    assert p.returncode == 0, p.stderr
    assert "NOT the same for every method" in p.stdout and "used by global" in p.stdout
    bad = _cli("simulate", "--robot", "planar_3r", "--algorithms", "jvja", "--global-start", "free")
    assert bad.returncode == 2 and "needs global among --algorithms" in bad.stderr


@pytest.mark.parametrize("objective", ["mean", "max"])
def test_global_scores_are_the_runs_own_and_never_beaten(objective):
    """meta['global']['scores'] are the runs' λ statistics; global is never above LNVA/JVJA."""
    arm = ft.load_arm("planar_3r")
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 1.0)
    q0 = ft.initial_posture(arm, [0.35, 0.0]).q
    stat = np.mean if objective == "mean" else np.max
    g = simulate(arm, path, "global", q0=q0, dt=0.01, plan_options={"objective": objective})
    locals_ = {a: simulate(arm, path, a, q0=q0, dt=0.01) for a in ("lnva", "jvja")}
    meta = g.meta["global"]
    assert meta["scores"]["final"] == pytest.approx(float(stat(g.jvj)), rel=1e-12)
    for a, r in locals_.items():
        assert meta["scores"][a] == pytest.approx(float(stat(r.jvj)), rel=1e-9)
        assert stat(g.jvj) <= stat(r.jvj) * (1 + 1e-12)
    best = min(float(stat(r.jvj)) for r in locals_.values())
    expect = max(0.0, (best - float(stat(g.jvj))) / best)
    assert meta["improvement_over_best_local"] == pytest.approx(expect, rel=1e-6, abs=1e-12)
    if meta["run"] != "plan" or meta["method"].startswith("warm start"):
        assert "note" in meta and f"the {objective} of λ" in meta["note"]  # says why


def test_objective_max_says_why_it_keeps_jvja_plan():
    """--objective max on the planar 3R: the printed line says why the plan is JVJA's run."""
    p = _cli("simulate", "--robot", "planar_3r", "--algorithms", "jvja,global", "--objective",
             "max", "--duration", "0.3")  # fmt: skip
    assert p.returncode == 0, p.stderr
    table = {
        ln.split()[0]: ln.split()[1:3]
        for ln in p.stdout.splitlines()
        if ln[:6] in ("jvja  ", "global")
    }
    if table["global"] == table["jvja"]:  # no change of plan: then a line says why
        assert "global: " in p.stdout and "max of λ" in p.stdout


def test_lock_reports_the_jump_at_the_lock_instant_with_units():
    """lock --at max: the planned run is the lock run's; λ ≡ 0 is said; the jump has units."""
    p = _cli("lock", "--robot", "planar_3r", "--joint", "joint2", "--lockable", "joint2",
             "--algorithm", "jvja", "--at", "max")  # fmt: skip
    assert p.returncode == 0, p.stderr
    assert "zero at every sample to rounding" in p.stdout
    line = next(ln for ln in p.stdout.splitlines() if ln.startswith("jump at the lock instant"))
    assert "t = 0.000 s" in line and "(rad/s)²" in line
    value = float(line.split("= ")[2].split(" ")[0])
    assert value < 1e-20  # the jump the run finds is the zero λ the planned run promised
    q = _cli(
        "lock", "--robot", "planar_3r", "--joint", "joint2", "--algorithm", "lnva", "--at", "max"
    )
    assert q.returncode == 0, q.stderr
    assert "(rad/s)², of which joint2's lock" in q.stdout


def test_replay_page_of_several_runs_names_start_and_winner(tmp_path):
    """A replay page of a folder of runs lists their start and the λ winners; one run: nothing."""
    pytest.importorskip("fault_tolerance.viz")
    from fault_tolerance.viz.page import export_html

    arm = ft.load_arm("planar_3r")
    q0 = ft.initial_posture(arm, [0.35, 0.0]).q
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 0.3)
    runs = {a: simulate(arm, path, a, q0=q0, dt=0.01) for a in ("lnva", "jvja")}
    for a, r in runs.items():
        r.save(tmp_path / "runs" / a)
    html = export_html(tmp_path / "runs", tmp_path / "page.html").read_text()
    block = html[html.index('<ul id="ft-comparison"') : html.index("</ul>")]
    assert "every method from the same q0" in block
    winner = compare_runs(runs).mean_winners[0]
    assert f"winner: λ mean {'='.join(winner)}" in block
    one = export_html(runs["jvja"], tmp_path / "one.html", arm).read_text()
    assert 'id="ft-comparison"' not in one


def test_report_table_names_the_winner_from_the_cases_one_start():
    """REPORT.md's λ table says which method won on mean and on max λ, ties named together."""
    from fault_tolerance.paper.report import write_report

    algs = {
        "lnva": {"jvj_mean": 3.0, "jvj_max": 5.0, "rcn_mean": 1.0, "rcn_max": 1.0},
        "jvja": {"jvj_mean": 2.0, "jvj_max": 5.0, "rcn_mean": 1.0, "rcn_max": 1.0},
        "mda": {"jvj_mean": 4.0, "jvj_max": 4.0, "rcn_mean": 1.0, "rcn_max": 1.0},
    }
    text = write_report({"cases": {"fig2": {"algorithms": algs}}})
    header = next(ln for ln in text.splitlines() if ln.startswith("| case | λ mean"))
    assert "winner (mean / max), from the case's one q0" in header
    row = next(ln for ln in text.splitlines() if ln.startswith("| fig2 | 3"))
    assert row.rstrip().endswith("| jvja / mda |")
