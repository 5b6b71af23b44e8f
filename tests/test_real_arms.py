"""Real robot descriptions (tests/data/robots): each loads, inspects, simulates and replays.

The descriptions come from public packages and repositories (manifest.json names each source);
they are what users bring: xacro packages, two-arm trees, mobile manipulators, continuous joints,
grippers with mimic joints, duplicate frame names. Meshes are not kept, so every load warns once
that their visuals are left out; that warning is expected here and nothing else is.
"""

from __future__ import annotations

import gc
import json
import subprocess
import sys
import warnings

import numpy as np
import pinocchio as pin
import pytest
from real_arms import ARMS, DATA, cli_args, load, package_dirs, path_args, source

import fault_tolerance as ft
from fault_tolerance.model.chains import serial_chains
from fault_tolerance.model.formats.build import build_model, read_description

NAMES = sorted(ARMS)
#: Samples with σ_min(J) below this are near-singular (the simulation flags < 1e-6; a real start
#: should stay far from that).
SIGMA_MIN_OK = 1e-3
#: Largest position tracking error accepted along the run [m].
TRACKING_OK = 1e-3


def _description(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_description(source(name), package_dirs(name), ARMS[name]["xacro_args"] or None)


def _cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "fault_tolerance", *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=cwd,
    )


RCN_WARNING = "with a reduced condition number beyond the paper's threshold"


def _only_expected_warnings(stderr: str) -> list[str]:
    """The stderr lines that are not the expected warnings (missing meshes, a shared frame name)."""
    return [
        line
        for line in stderr.splitlines()
        if line.strip()
        and not (
            line.startswith("fault-tolerance: warning: ")
            and (
                "mesh file(s) not found" in line
                or "is carried by 2 frames" in line
                or "mesh(es) not opened" in line  # replay: a mesh missing from the data set
            )
        )
    ]


# -- the data set covers what the issue asks for ------------------------------------------------


def test_at_least_eight_real_arms_with_sources_and_licenses():
    """Eight or more arms, each with its upstream source and license noted and its file present."""
    assert len(ARMS) >= 8
    for name, e in ARMS.items():
        assert source(name).is_file(), name
        assert e["upstream"] and e["license"], name
    assert (DATA / "NOTES.md").is_file()
    assert not list(DATA.rglob("*.stl")) + list(DATA.rglob("*.dae"))  # kinematics only


def test_the_set_has_xacro_packages_two_arm_trees_continuous_mimic_and_shared_names():
    """The properties the issue names hold in the files themselves, not only in the labels."""
    descs = {name: _description(name) for name in NAMES}
    xacro = [n for n in NAMES if ARMS[n]["source"].endswith(".xacro")]
    continuous = [n for n, d in descs.items() if d.continuous]
    mimic = [n for n, d in descs.items() if d.mimic]
    shared = []
    for n, d in descs.items():
        from lxml import etree

        root = etree.fromstring(d.data)
        links = {lk.get("name") for lk in root.findall("link")}
        if links & {j.get("name") for j in root.findall("joint")}:
            shared.append(n)
    two_arm = []
    for n, d in descs.items():
        chains = serial_chains(build_model(d), d.leaves, tuple(d.mimic), min_joints=6)
        arms = {c.joints[-1] for c in chains}  # distinct last joints: distinct arms
        if len(arms) >= 2 and len({c.joints[-6] for c in chains}) >= 2:
            two_arm.append(n)
    mobile = [n for n in NAMES if any("mobile" in c for c in ARMS[n]["covers"])]
    assert len(xacro) >= 3 and {"ur5e", "fr3"} <= set(xacro)
    assert {"pr2", "kinova"} <= set(continuous)
    assert {"fr3", "baxter", "pr2"} <= set(mimic)
    assert {"so100", "z1", "b1_z1"} <= set(shared)
    assert {"baxter", "pr2", "fr3_duo"} <= set(two_arm)
    assert {"pr2", "b1_z1"} <= set(mobile)


# -- each arm ---------------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_loads_with_the_manifest_options(name):
    """The arm loads with its tip, task and joints; q0 fits and is inside the limits."""
    e = ARMS[name]
    arm = load(name)
    q0 = np.array(e["q0"])
    assert arm.tip == e["tip"] and arm.n == len(q0) and arm.redundancy >= 1
    if e["joints"]:
        assert arm.joint_names == e["joints"]
    assert np.all((q0 >= arm.lower) & (q0 <= arm.upper))
    assert np.all(np.isfinite(arm.fk(q0))) and arm.jacobian(q0).shape == (arm.m, arm.n)


@pytest.mark.parametrize("name", NAMES)
def test_only_the_missing_mesh_warning(name):
    """Loading warns about the meshes we did not keep (their visuals left out) and nothing else
    but a shared frame name where the file has one."""
    gc.collect()  # other tests' garbage first, so its finalisers do not warn in here
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # jupyter_client's zmq sockets (test_notebooks) may still be collected mid-load; an
        # unclosed file or any other warning of the loader is still caught
        warnings.filterwarnings("ignore", message="Unclosed socket", category=ResourceWarning)
        _load_raw(name)
    texts = [str(w.message) for w in caught]
    assert any("mesh file(s) not found" in t for t in texts)
    assert all("mesh file(s) not found" in t or "is carried by 2 frames" in t for t in texts), texts
    assert sum("mesh file(s) not found" in t for t in texts) == 1


def _load_raw(name):
    e = ARMS[name]
    return ft.load_arm(
        source(name),
        tip=e["tip"],
        task=e["task"],
        joints=e["joints"],
        package_dirs=package_dirs(name),
        xacro_args=e["xacro_args"] or None,
    )


@pytest.mark.parametrize("name", NAMES)
def test_fk_is_pinocchios_on_the_full_model(name):
    """The reduced arm's tip placement is the full model's at the same joint values (others
    fixed at neutral): the reduction (with duplicate frame names renamed meanwhile) is exact."""
    arm = load(name)
    desc = _description(name)
    full = build_model(desc)
    q_full = pin.neutral(full)
    q0 = np.array(ARMS[name]["q0"])
    for jname, v in zip(arm.joint_names, q0, strict=True):
        j = full.joints[full.getJointId(jname)]
        if j.nq == 2:  # continuous joints are read as revolute, so nq == 1 always
            raise AssertionError(jname)
        q_full[j.idx_q] = v
    data = full.createData()
    pin.framesForwardKinematics(full, data, q_full)
    fid = next(
        i for i, f in enumerate(full.frames) if f.name == arm.tip and f.type == pin.FrameType.BODY
    )
    np.testing.assert_allclose(arm.placement(q0).homogeneous, data.oMf[fid].homogeneous, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_inspect_simulate_and_replay_from_the_command_line(name, tmp_path):
    """``inspect`` (exit 0, the chain and serial chains listed), ``simulate`` from the default start
    (no ``--q0``/``--x0``; inside the limits, never near-singular, position error < 1 mm) and
    ``replay --html``; no Pinocchio exception or traceback on stderr."""
    e = ARMS[name]
    opts = cli_args(name)
    target, rest = opts[1], opts[2:]  # inspect takes the file as its target, and no --lockable
    if "--lockable" in rest:
        rest = rest[: rest.index("--lockable")]
    p = _cli("inspect", target, *rest)
    assert p.returncode == 0, p.stderr
    assert f"chain to tip '{e['tip']}'" in p.stdout and "serial chains" in p.stdout
    assert not _only_expected_warnings(p.stderr), p.stderr

    out = tmp_path / "run"
    p = _cli(
        "simulate", *opts, *path_args(name), "--algorithms", "jvja", "--out", str(out),
        "--no-progress",
    )  # fmt: skip
    assert p.returncode == 0, p.stderr
    # the diagnostics may say that k_S passes the paper's RCN threshold of 100 (a quality warning
    # that the start rules do not exclude); any other warning (velocity, near-singular,
    # near-intolerable, off the path) fails
    assert not [line for line in _only_expected_warnings(p.stderr) if RCN_WARNING not in line], (
        p.stderr
    )
    arm = load(name)
    run = np.load(out / "jvja" / "run.npz")
    q = run["q"]
    assert np.all((q >= arm.lower - 1e-9) & (q <= arm.upper + 1e-9)), "a sample outside the limits"
    assert run["sigma_min"].min() > SIGMA_MIN_OK
    lin = [i for i, r in enumerate(arm.task) if r in ("x", "y", "z")]
    pos_err = np.linalg.norm(run["x"][:, lin] - run["x_des"][:, lin], axis=1)
    assert pos_err.max() < TRACKING_OK
    summary = json.loads((out / "jvja" / "summary.json").read_text())
    assert summary["summary"]["near_singular_samples"] == 0

    html = tmp_path / "replay.html"
    dirs = [
        a for d in package_dirs(name) for a in ("--package-dir", d)
    ]  # meshes: named folders only
    p = _cli("replay", str(out / "jvja"), "--html", str(html), *dirs)
    assert p.returncode == 0, p.stderr
    assert not _only_expected_warnings(p.stderr), p.stderr
    assert html.stat().st_size > 1000 and "<html" in html.read_text()[:2000].lower()


@pytest.mark.parametrize("name", NAMES)
def test_compiled_run_equals_the_reference_from_the_default_start(name):
    """From the arm's default start (its manifest's lockable joints, limits on), a JVJA run on the
    compiled sample equals the plain reference's: the commanded rates to
    1e-9 of their size, the same flags, and the jump λ = Σ w_S ‖ˢq̇' − q̇‖² within what rates
    that close allow, |Δλ| ≤ 2 (2 δ) √(W λ) (Cauchy-Schwarz, δ the rates' tolerance, W = Σ w_S).

    (PR2 under limits: λ agrees to 1.06e-9 relative at one bounded sample, with its rates to
    7e-10: the compiled bounded solver and the reference's active set round differently.)"""
    from fault_tolerance.simulation.paths import CirclePath
    from fault_tolerance.simulation.simulate import simulate

    e = ARMS[name]
    arm = load(name)
    lockable = e["lockable"] or None
    args = e.get("path_args", [])
    radius = float(args[args.index("--radius") + 1]) if "--radius" in args else 0.05

    def circle(x0):  # the CLI's default circle (1 s), with the manifest's radius
        return CirclePath(x0, radius, 2 * np.pi, 1.0)

    q0 = ft.default_start(arm, lockable, path=circle).q0
    path = CirclePath(arm.fk(q0), radius, 2 * np.pi, 0.2)
    fast = simulate(arm, path, "jvja", q0=q0, lockable=lockable, engine="fast")
    ref = simulate(arm, path, "jvja", q0=q0, lockable=lockable, engine="reference")
    delta = 1e-9 * max(1.0, float(np.abs(ref.qd).max()))
    np.testing.assert_allclose(fast.qd, ref.qd, rtol=0, atol=delta)
    W = float(np.sum(fast.meta.get("weights") or np.ones(fast.jvj_parts.shape[1])))
    bound = 4.0 * delta * np.sqrt(W * np.abs(ref.jvj)) + 1e-12
    assert np.all(np.abs(fast.jvj - ref.jvj) <= bound), np.max(np.abs(fast.jvj - ref.jvj) / bound)
    np.testing.assert_array_equal(fast.flags, ref.flags)
