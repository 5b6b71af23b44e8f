"""A saved run is untrusted input: truncated, ragged, mistyped or forged run files are one-line errors."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from fault_tolerance.errors import InvalidInput
from fault_tolerance.storage.run_file import SHAPES, read_run_file

REQUIRED = tuple(k for k in SHAPES if k != "qd_cmd")
K, N, M, F = 6, 3, 2, 3


def arrays() -> dict:
    """A consistent set of run arrays (K samples, N joints, M task rows, F scenarios)."""
    size = {"K": K, "n": N, "m": M, "f": F}
    out = {k: np.zeros(tuple(size[s] for s in shape)) for k, shape in SHAPES.items()}
    out["t"] = np.arange(K) * 1e-3
    out["flags"] = np.zeros(K, dtype=np.int64)
    return out


META = {"robot": "planar_3r", "algorithm": "jvja", "dt": 1e-3, "joint_names": ["a", "b", "c"]}


def save(path, meta=META, **changes) -> None:
    """Write a run file with ``changes`` to the arrays (None removes one)."""
    a = arrays()
    for k, v in changes.items():
        if v is None:
            a.pop(k)
        else:
            a[k] = v
    text = meta if isinstance(meta, str) else json.dumps(meta)
    buf = io.BytesIO()
    np.savez_compressed(buf, meta=np.array(text), **a)
    path.write_bytes(buf.getvalue())


def test_a_consistent_file_reads(tmp_path):
    """The reference file passes every check."""
    save(tmp_path / "run.npz")
    got, meta, arm = read_run_file(tmp_path / "run.npz", REQUIRED)
    assert got["q"].shape == (K, N) and meta["robot"] == "planar_3r" and arm is None


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"q": np.zeros((K - 1, N))}, "ragged"),
        ({"x_des": np.zeros((K, M + 1))}, "ragged"),
        ({"rcn": np.zeros((K, F, 2))}, "must be \\(K, f\\)"),
        ({"jvj": None}, "lacks arrays \\['jvj'\\]"),
        ({"t": np.array([0, 1, 1, 2, 3, 4.0])}, "strictly increasing"),
        ({"t": np.array([0, 1, np.nan, 2, 3, 4.0])}, "finite"),
        ({"q": np.full((K, N), np.inf)}, "must be finite"),
        ({"q": np.zeros((K, N), dtype=complex)}, "must hold numbers"),
        ({"q": np.array([["a"] * N] * K)}, "must hold numbers"),
        ({"evil": np.zeros(3)}, "unknown arrays"),
        ({"t": np.zeros(0), **{k: None for k in SHAPES if k != "t"}}, "lacks arrays"),
    ],
)
def test_ragged_or_mistyped_arrays_are_refused(tmp_path, changes, match):
    """Arrays that disagree in K, n, m or f, lack one, hold non-numbers or bad times: one line."""
    save(tmp_path / "run.npz", **changes)
    with pytest.raises(InvalidInput, match=match) as info:
        read_run_file(tmp_path / "run.npz", REQUIRED)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "meta, match",
    [
        ("[1, 2, 3]", "must be a JSON object"),
        ('"text"', "must be a JSON object"),
        ("{not json", "is not JSON"),
        ("[" * 100_000 + "]" * 100_000, "not JSON|JSON object"),
        ({**META, "dt": "fast"}, "'dt' has type str"),
        ({**META, "dt": True}, "'dt' has type bool"),
        ({**META, "joint_names": "abc"}, "'joint_names' has type str"),
        ({**META, "joint_names": [1, 2, 3]}, "list of names"),
        ({**META, "joint_names": ["a"]}, "names 1 joints, the arrays have 3"),
        ({**META, "lock": {"joint": "b", "time": "soon"}}, "lock time must be a finite number"),
        ({**META, "lock": {"joint": "b", "time": float("nan")}}, "lock time must be a finite"),
        ({**META, "lock": {"joint": "b", "time": 0.1, "index": 7}}, "index 7 is not a joint"),
        ({**META, "lock": {"joint": 3, "time": 0.1}}, "locked joint must be a name"),
        ({**META, "lock": [1]}, "'lock' has type list"),
    ],
)
def test_bad_metadata_is_refused(tmp_path, meta, match):
    """meta that is not an object, not JSON, or with fields of the wrong type or value: one line."""
    save(tmp_path / "run.npz", meta=meta)
    with pytest.raises(InvalidInput, match=match):
        read_run_file(tmp_path / "run.npz", REQUIRED)


@pytest.mark.parametrize("keep", [0.1, 0.5, 0.9, 0.99])
def test_truncated_files_are_refused(tmp_path, keep):
    """A run file cut at any point (a full disk, a partial copy) is refused in one line."""
    save(tmp_path / "run.npz")
    data = (tmp_path / "run.npz").read_bytes()
    (tmp_path / "run.npz").write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(InvalidInput, match="not a readable run file|truncated") as info:
        read_run_file(tmp_path / "run.npz", REQUIRED)
    assert "\n" not in str(info.value)
