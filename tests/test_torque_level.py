"""paper/torque_level.py: REPORT.md's section "The lock at torque level"."""

from __future__ import annotations

import numpy as np

from fault_tolerance.paper.torque_level import FIGURES, report_section, torque_level, verdicts


def _entry(jumps, torques, ratio=0.5):
    algs = {
        a: {b: {**dict.fromkeys(FIGURES, 0.1), "jump_at_lock": j, "torque_jump_max": t,
                "torque_peak_ratio": ratio} for b in ("ideal", "finite")}
        for a, j, t in zip(("lnva", "jvja", "mda"), jumps, torques, strict=True)
    }  # fmt: skip
    return {"title": "arm", "joint": "joint2", "brake_torque": 5.0, "algorithms": algs}


def test_verdict_says_plainly_where_the_minima_part():
    """Different minimisers are 'not the same'; ties count as the same; saturation is named."""
    assert "**not the same**" in verdicts({"a": _entry([1, 0.5, 2], [1, 3, 0.2])})[0]
    same = verdicts({"a": _entry([0.0, 0.0, 2], [3, 1, 1 + 1e-9])})[0]
    assert "the same." in same and "not" not in same
    assert "saturates" in verdicts({"a": _entry([1, 2, 3], [1, 2, 3], ratio=1.0)})[0]


def test_planar_3r_section_runs_every_planner_and_both_brakes():
    """On the Fig. 2 arm every planner and brake has finite figures; the section has its table."""
    data = torque_level(["fig2"])
    entry = data["fig2"]
    assert set(entry["algorithms"]) == {"lnva", "jvja", "jvja_inertia", "mda", "global"}
    for by_brake in entry["algorithms"].values():
        for s in by_brake.values():
            assert all(np.isfinite(s[k]) for k in FIGURES)
            assert s["lock_impulse"] > 0
    # D4: on this r = 1 arm the inertia-weighted JVJA plans JVJA's rates
    a, b = entry["algorithms"]["jvja"]["ideal"], entry["algorithms"]["jvja_inertia"]["ideal"]
    np.testing.assert_allclose(b["jump_at_lock"], a["jump_at_lock"], rtol=1e-8)
    text = report_section(data)
    assert text.startswith("## The lock at torque level")
    assert "Does the minimum velocity jump mean the minimum torque jump?" in text
