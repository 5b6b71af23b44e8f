"""Bounded work: steps, memory, frames and saved-run sizes are estimated and refused up front."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from fault_tolerance.errors import InvalidInput
from fault_tolerance.storage import budget


@pytest.mark.parametrize(
    "dt, duration, match",
    [
        (1e-300, 1.0, "at most 1,000,000"),
        (1e-3, 1e9, "shorten --duration"),
        (1e-3, float("inf"), "finite"),
        (0.0, 1.0, "finite number > 0"),
        (float("nan"), 1.0, "finite number > 0"),
    ],
)
def test_too_many_samples_are_refused(dt, duration, match):
    """A run longer than MAX_RUN_SAMPLES samples (or with a non-finite time) is refused by name."""
    with pytest.raises(InvalidInput, match=match):
        budget.run_samples(dt, duration)


def test_samples_within_the_limit():
    """duration / dt + 1 samples, as simulate records them."""
    assert budget.run_samples(1e-3, 1.0) == 1001
    assert budget.run_samples(1e-3, 999.0) == 999_001


def test_memory_is_checked_before_allocating(monkeypatch):
    """Runs whose arrays exceed the memory budget are refused naming the MiB needed and allowed."""
    monkeypatch.setattr(budget, "available_memory", lambda: 100 * 2**20)
    assert budget.memory_budget() == 50 * 2**20
    with pytest.raises(InvalidInput, match="MiB; at most 50 MiB"):
        budget.check_run(1e-3, 900.0, n=100, m=6, f=100, runs=3)
    assert budget.check_run(1e-3, 1.0, n=7, m=6, f=7) == 1001


def test_run_bytes_counts_every_array():
    """run_bytes matches the arrays simulate keeps (t, q, qd, qd_cmd, x, x_des, ... ) for 1 sample."""
    n, m, f = 3, 2, 3
    arrays = 6 * 8 + 3 * n * 8 + 2 * m * 8 + 2 * f * 8
    assert budget.run_bytes(1, n, m, f) == arrays


def test_replay_frames_are_bounded():
    """A replay slowed down until it has too many frames is refused naming --speed."""
    assert budget.check_frames(1.0, 1.0, 50.0) == 50
    with pytest.raises(InvalidInput, match="--speed"):
        budget.check_frames(1.0, 1e-9, 50.0)


def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def test_npz_members_reads_headers_only(tmp_path):
    """Shapes and dtypes of a saved run's arrays come from their headers."""
    path = tmp_path / "run.npz"
    path.write_bytes(_npz(t=np.zeros(5), q=np.zeros((5, 3)), meta=np.array("{}")))
    got = budget.npz_members(path)
    assert got["t"][0] == (5,) and got["q"][0] == (5, 3) and got["meta"][1].kind == "U"


def _forged(header_shape: str) -> bytes:
    """An npz whose member declares ``header_shape`` but holds 80 bytes of data."""
    from numpy.lib import format as npformat

    head = io.BytesIO()
    npformat.write_array_header_1_0(
        head, {"descr": "<f8", "fortran_order": False, "shape": eval(header_shape)}
    )
    member = head.getvalue()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("q.npy", member + b"\x00" * 80)
    return buf.getvalue()


@pytest.mark.parametrize("shape", ["(10**12,)", "(4, 4)", "(100000, 100000)"])
def test_a_forged_header_is_refused_before_numpy_allocates(tmp_path, shape):
    """A member whose header declares more (or less) data than it holds is refused; NumPy would
    otherwise allocate the declared shape (10¹² floats) before noticing."""
    path = tmp_path / "run.npz"
    path.write_bytes(_forged(shape))
    with pytest.raises(InvalidInput, match="truncated or forged"):
        budget.npz_members(path)


def test_too_large_or_foreign_members_are_refused(tmp_path, monkeypatch):
    """Arrays past MAX_RUN_FILE_BYTES decompressed, object arrays and non-.npy members are refused."""
    path = tmp_path / "run.npz"
    path.write_bytes(_npz(q=np.zeros(10_000)))
    with pytest.raises(InvalidInput, match="more than 1,000 bytes decompressed"):
        budget.npz_members(path, limit=1000)
    buf = io.BytesIO()
    np.savez(buf, o=np.array([{"a": 1}], dtype=object))
    path.write_bytes(buf.getvalue())
    with pytest.raises(InvalidInput, match="dtype object"):
        budget.npz_members(path)
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("evil.py", "print(1)")
    with pytest.raises(InvalidInput, match="not an array"):
        budget.npz_members(path)
    path.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(InvalidInput, match="not a readable run file"):
        budget.npz_members(path)


def test_path_files_are_bounded(tmp_path, monkeypatch):
    """A CSV path larger than MAX_PATH_FILE_BYTES, or with more rows than a run may have samples,
    or with too many columns is refused before it is parsed whole."""
    from fault_tolerance.simulation.paths import load_csv

    path = tmp_path / "p.csv"
    path.write_text("t,x,y\n" + "".join(f"{i * 1e-3},0.3,0\n" for i in range(50)))
    assert len(load_csv(path).t) == 50
    monkeypatch.setattr(budget, "MAX_PATH_FILE_BYTES", 100)
    with pytest.raises(InvalidInput, match="at most 100"):
        load_csv(path)
    monkeypatch.undo()
    monkeypatch.setattr(budget, "MAX_RUN_SAMPLES", 10)
    with pytest.raises(InvalidInput, match="more than 10 rows"):
        load_csv(path)
    path.write_text("t," + ",".join(f"c{i}" for i in range(70)) + "\n")
    with pytest.raises(InvalidInput, match="70|71 columns"):
        load_csv(path)
