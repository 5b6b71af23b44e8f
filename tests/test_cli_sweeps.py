"""The workspace and design commands: files written, resume, one-line errors."""

import json

import numpy as np
import pytest

from fault_tolerance.cli import EXAMPLES, main


@pytest.mark.parametrize("cmd", ["workspace", "design"])
def test_help_has_an_example(cmd, capsys):
    """--help shows an example and how to start a Dask cluster."""
    with pytest.raises(SystemExit):
        main([cmd, "--help"])
    out = capsys.readouterr().out
    assert "example:" in out and EXAMPLES[cmd].split("\n")[0][:40] in out and "dask worker" in out


@pytest.mark.parametrize("cmd", ["workspace", "design"])
def test_help_states_every_default(cmd, capsys):
    """Every option's help states its default, as numbers where it has one."""
    with pytest.raises(SystemExit):
        main([cmd, "--help"])
    out = " ".join(capsys.readouterr().out.split())
    if cmd == "workspace":
        from fault_tolerance.analysis.workspace.closed_form import CHUNKS, SAMPLES, THETA_SAMPLES

        for text in ("--grid GRID points per axis (default: 201 for a planar 3R;",
                     "24 for position", f"(default {SAMPLES})", f"(default: {THETA_SAMPLES} for",
                     f"(default {CHUNKS})"):  # fmt: skip
            assert text in out, text
    assert "--grid GRID" in out and "--no-progress no progress bar (default:" in out
    options = out.split("robot:")[0].replace("output folder (required; default: none)", "")
    assert "(default: none)" not in options


def test_workspace_writes_json_npz_png_and_resumes(tmp_path, capsys):
    """workspace writes its three files with areas in m², limits in rad; a rerun reuses chunks."""
    out = tmp_path / "ws"
    args = [
        "workspace",
        "--robot",
        "planar_3r",
        "--limits=-60:60,-120:120,-120:120",
        "--deg",
        "--grid",
        "41",
        "--samples",
        "20",
        "--workers",
        "0",
        "--out",
        str(out),
        "--no-progress",
    ]
    assert main(args) == 0
    rec = json.loads((out / "workspace.json").read_text())
    np.testing.assert_allclose(rec["limits"][0], np.deg2rad([-60, 60]))
    assert rec["robot"] == "planar_3r" and rec["grid"] == 41 and rec["area_ftw"] > 0
    assert rec["area_pre"] > rec["area_ftw"] and "definition" in rec and "resolution" in rec
    z = np.load(out / "workspace.npz")
    assert z["ftw"].shape == (41, 41) and (out / "workspace.png").stat().st_size > 0
    chunks = sorted(out.glob("chunks-*/chunk-*.npz"))
    assert len(chunks) == 16
    stamp = [c.stat().st_mtime_ns for c in chunks]
    assert main(args) == 0
    assert [c.stat().st_mtime_ns for c in chunks] == stamp  # resumed, not recomputed
    assert json.loads((out / "workspace.json").read_text())["area_ftw"] == rec["area_ftw"]


def test_spatial_workspace_reports_volumes(tmp_path):
    """A position task reports volumes in m³."""
    out = tmp_path / "sp"
    assert (
        main(
            [
                "workspace",
                "--robot",
                "spatial_4r",
                "--grid",
                "8",
                "--samples",
                "2000",
                "--theta-samples",
                "3",
                "--workers",
                "0",
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    rec = json.loads((out / "workspace.json").read_text())
    assert rec["volume_pre"] > 0 and "area_ftw" not in rec


def test_design_writes_json_and_png(tmp_path):
    """design writes design.json (limits in rad, area, jvj, rcn) and design.png."""
    out = tmp_path / "d"
    assert (
        main(
            [
                "design",
                "--robot",
                "planar_3r",
                "--objective",
                "ftw-area",
                "--candidates",
                "4",
                "--rounds",
                "0",
                "--grid",
                "31",
                "--workers",
                "0",
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    rec = json.loads((out / "design.json").read_text())
    assert len(rec["limits"]) == 3 and rec["area_ftw"] >= 0 and "jvj" in rec and "rcn" in rec
    assert (out / "design.png").stat().st_size > 0


@pytest.mark.parametrize(
    "argv, words",
    [
        (["workspace", "--robot", "planar_3r", "--limits=-5:1,0:1,0:1"], "physical"),
        (["workspace", "--robot", "planar_3r", "--limits", "a:b"], "lo:hi"),
        (["workspace", "--robot", "planar_3r", "--workers", "-1"], "workers"),
        (["design", "--robot", "spatial_4r"], "planar 3R"),
        (["design", "--robot", "planar_3r", "--objective", "fast"], "objective"),
        (["design", "--robot", "planar_3r", "--task", "square"], "circle"),
        (["workspace", "--robot", "spatial_4r", "--chunks", "4"], "planar-3R method"),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path, capsys, argv, words):
    """Bad input: exit 2 and one line on stderr naming the problem."""
    assert main(argv + ["--out", str(tmp_path / "x"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and words in err
