"""Design of a planar 3R: limits and links, objectives, Pareto front, bad input."""

import json

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.analysis.design.planar import scaled_arm
from fault_tolerance.analysis.design.search import design, pareto
from fault_tolerance.errors import InvalidInput
from fault_tolerance.figures.design import plot_design
from fault_tolerance.model.planar import planar_chain


def test_scaled_arm_has_the_lengths_asked_for():
    """Rescaled placements give the new link lengths; Pinocchio's FK agrees with the chain."""
    arm = scaled_arm(ft.load_arm("planar_3r"), [0.6, 0.5, 0.4])
    np.testing.assert_allclose(planar_chain(arm).lengths, [0.6, 0.5, 0.4], atol=1e-12)
    np.testing.assert_allclose(arm.fk(np.zeros(3)), [1.5, 0.0], atol=1e-12)


def test_pareto_front():
    """pareto keeps exactly the rows no other row beats in both coordinates."""
    pts = np.array([[1, 5], [2, 2], [3, 1], [3, 3], [np.nan, 0], [1, 6]], dtype=float)
    assert sorted(pareto(pts)) == [0, 1, 2]


def test_area_design_beats_no_limits(tmp_path):
    """The chosen limits have a failure-tolerant area >= the arm without artificial limits."""
    arm = ft.load_arm("planar_3r")
    d = design(arm, objective="ftw-area", candidates=6, rounds=1, grid=41, folder=tmp_path)
    assert d.record["area_ftw"] > d.record["baseline"]["area_ftw"] == 0.0
    assert min(d.evaluated["score"]) <= d.evaluated["score"][0]
    lim = np.array(d.record["limits"])
    assert np.all(lim[:, 0] >= arm.lower - 1e-12) and np.all(lim[:, 1] <= arm.upper + 1e-12)
    d.save(tmp_path, draw=plot_design)
    rec = json.loads((tmp_path / "design.json").read_text())
    assert {"limits", "area_ftw", "jvj", "rcn", "pareto"} <= set(rec)
    assert (tmp_path / "design.png").stat().st_size > 0


def test_jvj_design_with_links_and_rcn_requirement():
    """Links keep their sum, the requirement holds, and the front is mutually non-dominated."""
    arm = ft.load_arm("planar_3r")
    d = design(arm, "links,limits", "jvj", rcn_max=40.0, candidates=6, rounds=0, grid=31)
    rec = d.record
    assert abs(sum(rec["links"]) - 1.5) < 1e-12
    assert rec["rcn_max"] <= 40.0 * 1.05  # searched at dt 2 ms, reported at 1 ms
    s = d.evaluated
    ok = np.isfinite(s["score"])
    assert rec["jvj"] <= 1.05 * np.min(s["jvj"][ok])
    front = np.array([[p["jvj"], p["rcn"]] for p in rec["pareto"]])
    assert len(front) >= 1
    for p in front:
        assert not np.any(np.all(front <= p, 1) & np.any(front < p, 1))


def test_bad_design_input():
    """A non-planar arm, unknown objectives and unknown variations raise InvalidInput."""
    with pytest.raises(InvalidInput, match="planar 3R"):
        design(ft.load_arm("spatial_4r"))
    with pytest.raises(InvalidInput, match="objective"):
        design(ft.load_arm("planar_3r"), objective="speed")
    with pytest.raises(InvalidInput, match="vary"):
        design(ft.load_arm("planar_3r"), vary="links")
