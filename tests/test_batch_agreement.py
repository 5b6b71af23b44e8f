"""The batched API agrees with the scalar API within BATCH_RTOL, on random and ill-conditioned rows."""

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.analysis.batch_agreement import BATCH_RTOL, batch_agreement
from fault_tolerance.numerics.linalg import SIGMA_EPS

CASES = [
    ("planar_3r", {}, [0, 1, 2]),
    ("spatial_4r", {}, [0, 1, 2]),
    ("powercube_3r", {}, [0, 1, 2]),
    ("panda", {"task": "position"}, [0, 1, 2, 3, 4, 5, 6]),
    ("panda", {"task": "pose"}, [0, 1, 2, 3, 4, 5, 6]),
]
QUANTITIES = ("lnva", "jvja", "jvja_continuation", "jvj", "rcn")


@pytest.mark.parametrize(
    "name,kw,lockable", CASES, ids=[f"{c[0]}-{c[1].get('task', '')}" for c in CASES]
)
def test_batched_api_within_the_documented_tolerance(name, kw, lockable):
    """Every rate, λ and k_S of ft.batch is within BATCH_RTOL (docs/batch.md) of the scalar API."""
    arm = ft.load_arm(name, **kw)
    res = batch_agreement(arm, lockable, random_rows=150, ill_rows=150, seed=7)
    worst = {k: res["all"][k] for k in QUANTITIES}
    assert max(worst.values()) < BATCH_RTOL, worst


def test_ill_rows_reach_the_damped_regime():
    """The ill-conditioned rows include σ_min(J) far below SIGMA_EPS (the damped pseudo-inverse)."""
    res = batch_agreement(ft.load_arm("planar_3r"), [0, 1, 2], random_rows=0, ill_rows=200)
    assert res["ill"]["sigma_min"] < 1e-3 * SIGMA_EPS
    assert res["random"]["rows"] == 0 and res["ill"]["rows"] == 200


def test_the_docs_quote_the_tolerance_and_the_measured_maximum():
    """docs/batch.md states BATCH_RTOL and a measured maximum below it."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "batch.md").read_text(encoding="utf-8")
    assert f"BATCH_RTOL = {BATCH_RTOL:g}" in text
    measured = float(text.split("all 20 000 rows is **")[1].split("**")[0])
    assert 0 < measured < BATCH_RTOL
    assert np.isfinite(measured)
