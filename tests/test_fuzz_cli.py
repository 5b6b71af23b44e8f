"""Fuzzing the command line and saved runs: every input gives exit 0 or 2, one line, no traceback.

``fault_tolerance.cli.main`` is called in-process (argparse's own errors are its ``SystemExit(2)``).
Each example is bounded: options that set the length of a run are drawn either invalid or small, so
a run the limits let through takes a fraction of a second; a run the limits refuse must be refused
before any work. Exit 1 (an unexpected failure, i.e. a bug) fails the test with the message.
"""

from __future__ import annotations

import io
import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fault_tolerance.cli import main

FUZZ = settings(
    max_examples=10,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    derandomize=True,
)

#: Texts that have broken number parsing before, and a few plain ones.
ODD = [
    "",
    ",",
    ",,",
    " ",
    "nan",
    "inf",
    "-inf",
    "1e-300",
    "1e9",
    "1e308",
    "-1",
    "0",
    "abc",
    "1,2",
    "0x10",
    "1_000",
    "١",
    "∞",
    "--",
]


def call(argv: list[str], capsys) -> tuple[int, str]:
    """Exit code and stderr of ``fault-tolerance ARGV`` in this process."""
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse: usage errors (2) and --help (0)
        rc = exc.code if isinstance(exc.code, int) else 2
    err = capsys.readouterr().err
    return rc, err


def check(rc: int, err: str, argv) -> None:
    """Exit 0 or 2; on 2 exactly one line on stderr; never a traceback."""
    assert "Traceback" not in err, (argv, err)
    assert rc in (0, 2), (argv, rc, err)
    if rc == 2:
        assert err.count("\n") == 1 or err.strip().startswith("usage:"), (argv, err)


def numbers(good: st.SearchStrategy) -> st.SearchStrategy:
    """A number option's text: a good value, an odd text, any float, or random text."""
    return st.one_of(
        good.map(repr),
        st.sampled_from(ODD),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        st.text(st.characters(blacklist_characters="\x00"), max_size=6),
    )


# small when valid: a run the limits let through stays short
SHORT = st.floats(min_value=0.003, max_value=0.02)
STEP = st.floats(min_value=1e-3, max_value=0.01)
NAMES = st.lists(
    st.sampled_from(
        ["joint1", "joint2", "joint3", "joint9", "", " ", "all", "a+b", "joint1+joint2"]
    ),
    max_size=4,
).map(",".join)

OPTIONS = {
    "--dt": numbers(STEP),
    "--duration": numbers(SHORT),
    "--radius": numbers(st.floats(min_value=0.0, max_value=0.2)),
    "--omega": numbers(st.floats(min_value=-10, max_value=10)),
    "--feedback": numbers(st.floats(min_value=0, max_value=50)),
    "--gain": numbers(st.floats(min_value=0, max_value=1)),
    "--x0": st.one_of(st.sampled_from(ODD), st.just("0.35,0"), st.just("9,9"), st.just("0.35")),
    "--q0": st.one_of(st.sampled_from(ODD), st.just("0.3,1.2,1.0"), st.just("0.3,1.2")),
    "--lockable": NAMES,
    "--joints": NAMES,
    "--rows": st.sampled_from(["x,y", "y,x", "x,x", "x", "z,y", ",", "x,y,z"]),
    "--algorithms": st.sampled_from(["lnva", "jvja,mda", ",", "", "nope", "lnva,lnva"]),
    "--tip": st.sampled_from(["tool", "base", "nope", ""]),
    "--task": st.sampled_from(["planar", "position", "pose", "x,y", "x", "", ",", "rx,rz", "q"]),
}


@FUZZ
@given(
    picks=st.dictionaries(st.sampled_from(sorted(OPTIONS)), st.none(), min_size=1, max_size=3),
    data=st.data(),
)
def test_simulate_options(picks, data, capsys, tmp_path_factory):
    """simulate with fuzzed options: 0 or 2, one line, no traceback, bounded work."""
    argv = ["simulate", "--robot", "planar_3r", "--no-progress", "--duration", "0.01"]
    for opt in picks:
        argv += [opt, data.draw(OPTIONS[opt], label=opt)]
    check(*call(argv, capsys), argv)


@FUZZ
@given(
    at=numbers(st.floats(min_value=0.0, max_value=0.01)) | st.sampled_from(["max", "min", "mean"]),
    tau=numbers(st.floats(min_value=0.0, max_value=0.1)),
    joint=st.sampled_from(["joint1", "joint3", "joint7", "", "1"]),
)
def test_lock_options(at, tau, joint, capsys):
    """lock with fuzzed --at, --tau and --joint: 0 or 2."""
    argv = ["lock", "--robot", "planar_3r", "--no-progress", "--duration", "0.01", "--joint", joint]
    argv += ["--at", at, "--tau", tau]
    check(*call(argv, capsys), argv)


CASES = ["fig2", "fig3", "fig4", "fig6", "fig7", "experiment"]


@FUZZ
@given(cases=st.lists(st.sampled_from(CASES + ["", " ", "fig5", "FIG2", "all", ".."]), max_size=4))
def test_reproduce_cases_lists(cases, capsys, tmp_path_factory):
    """reproduce --cases with empty items or unknown names: exit 2 before any work."""
    text = ",".join(cases)
    if cases and all(c in CASES for c in cases):
        return  # a valid subset runs the paper's cases (tests/test_experiments.py does that)
    out = tmp_path_factory.mktemp("rep")
    argv = ["reproduce", "--quick", "--no-progress", "--out", str(out), "--cases", text]
    rc, err = call(argv, capsys)
    check(rc, err, argv)
    assert rc == 2 and not (out / "summary.json").exists(), (argv, err)


@pytest.mark.slow
@FUZZ
@given(
    name=st.one_of(
        st.text(st.characters(blacklist_characters="\x00/"), min_size=1, max_size=20),
        st.integers(200, 400).map(lambda k: "n" * k),
        st.sampled_from([".", "..", "a/b/c", "-x", " "]),
    )
)
def test_output_names(name, capsys, tmp_path_factory):
    """simulate --out with odd or too long names: 0 or 2 (a name the file system refuses is 2)."""
    root = tmp_path_factory.mktemp("names")
    argv = ["simulate", "--robot", "planar_3r", "--no-progress", "--duration", "0.005"]
    argv += ["--algorithms", "lnva", "--out", str(root / name)]
    check(*call(argv, capsys), argv)


def test_a_name_too_long_is_exit_2(capsys, tmp_path):
    """--out with a 300-byte name: exit 2, one line naming the limit, nothing created."""
    argv = ["simulate", "--robot", "planar_3r", "--no-progress", "--q0", "0.3,1.2,1.0"]
    argv += ["--duration", "0.005", "--out", str(tmp_path / ("n" * 300))]
    rc, err = call(argv, capsys)
    check(rc, err, argv)
    assert rc == 2 and "longer than this file system allows" in err
    assert list(tmp_path.iterdir()) == []


# -- saved runs -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A short planar 3R run saved by the command line."""
    out = tmp_path_factory.mktemp("saved")
    assert main(["simulate", "--robot", "planar_3r", "--no-progress", "--duration", "0.02",
                 "--algorithms", "jvja", "--out", str(out)]) == 0  # fmt: skip
    return out / "jvja"


JSON = st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=8,
)


def _rewrite(folder: Path, mutate) -> None:
    """Apply ``mutate(members)`` to run.npz's members, then re-record the folder as complete."""
    from fault_tolerance.storage.result_folder import write_record

    with np.load(folder / "run.npz", allow_pickle=False) as z:
        members = {k: z[k] for k in z.files}
    mutate(members)
    buf = io.BytesIO()
    np.savez_compressed(buf, **members)
    (folder / "run.npz").write_bytes(buf.getvalue())
    write_record(folder)


MUTATIONS = st.sampled_from(
    [
        "drop",
        "shorten",
        "widen",
        "nan",
        "type",
        "meta_value",
        "meta_field",
        "arm_value",
        "arm_field",
    ]
)


@FUZZ
@given(how=MUTATIONS, key=st.sampled_from(["t", "q", "x_des", "flags", "jvj", "meta", "arm"]),
       value=JSON, field=st.sampled_from(["lock", "joint_names", "dt", "task", "tip", "urdf", "joints",
                                           "q_full", "kind", "format"]))  # fmt: skip
def test_replay_of_a_tampered_run(saved, how, key, value, field, capsys, tmp_path_factory):
    """replay of a run whose arrays, meta or carried arm were altered (and re-recorded, so the
    completion check passes): 0 or 2, one line, no traceback."""
    folder = tmp_path_factory.mktemp("tampered") / "run"
    shutil.copytree(saved, folder)

    def mutate(m):
        if how == "drop":
            m.pop(key, None)
        elif how == "shorten" and key not in ("meta", "arm"):
            m[key] = m[key][:-1]
        elif how == "widen" and key not in ("meta", "arm"):
            m[key] = np.stack([m[key], m[key]], axis=-1)
        elif how == "nan" and key not in ("meta", "arm"):
            m[key] = np.full(m[key].shape, np.nan)
        elif how == "type" and key not in ("meta", "arm"):
            m[key] = np.array(["x"] * len(m[key]))
        elif how in ("meta_value", "arm_value"):
            m[how[:-6] if how == "meta_value" else "arm"] = np.array(json.dumps(value))
        elif how in ("meta_field", "arm_field"):
            which = "meta" if how == "meta_field" else "arm"
            doc = json.loads(str(m[which]))
            doc[field] = value
            m[which] = np.array(json.dumps(doc))

    _rewrite(folder, mutate)
    argv = ["replay", str(folder), "--html", str(folder.parent / "r.html")]
    check(*call(argv, capsys), argv)


@FUZZ
@given(cut=st.floats(0.0, 1.0), flip=st.integers(0, 10_000))
def test_replay_of_a_corrupted_file(saved, cut, flip, capsys, tmp_path_factory):
    """A run.npz truncated or with a flipped byte, recorded or not: exit 2 in one line."""
    from fault_tolerance.storage.result_folder import write_record

    folder = tmp_path_factory.mktemp("corrupt") / "run"
    shutil.copytree(saved, folder)
    data = bytearray((folder / "run.npz").read_bytes())
    data = data[: max(1, int(len(data) * cut))]
    data[flip % len(data)] ^= 0xFF
    (folder / "run.npz").write_bytes(bytes(data))
    if flip % 2:
        write_record(folder)  # forged: the record matches the damaged file
    argv = ["replay", str(folder), "--html", str(folder.parent / "r.html")]
    rc, err = call(argv, capsys)
    check(rc, err, argv)
    assert rc == 2


def test_zip_bomb_member_is_refused(saved, capsys, tmp_path, monkeypatch):
    """A run.npz whose member inflates past the saved-run limit (here lowered to 8 MiB) is refused
    from the zip directory, before anything is inflated."""
    from fault_tolerance.storage import budget
    from fault_tolerance.storage.result_folder import write_record

    monkeypatch.setattr(budget, "MAX_RUN_FILE_BYTES", 8 << 20)
    MAX_RUN_FILE_BYTES = budget.MAX_RUN_FILE_BYTES
    folder = tmp_path / "bomb"
    shutil.copytree(saved, folder)
    with zipfile.ZipFile(folder / "run.npz", "a", zipfile.ZIP_DEFLATED) as zf:
        with zf.open("qd_cmd.npy", "w", force_zip64=True) as fh:
            chunk = b"\x00" * (1 << 24)
            for _ in range(MAX_RUN_FILE_BYTES // len(chunk) + 1):
                fh.write(chunk)
    write_record(folder)
    rc, err = call(["replay", str(folder), "--html", str(tmp_path / "r.html")], capsys)
    assert rc == 2 and "decompressed" in err, err
