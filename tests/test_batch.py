"""The batched API equals the scalar one row by row."""

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.analysis import batch
from fault_tolerance.errors import IntolerableFailure, InvalidInput

ARMS = [
    ("planar_3r", {}, [0, 1, 2]),
    ("spatial_4r", {}, [0, 1, 2]),
    ("panda", {"task": "position"}, [0, 1, 2, 3, 4]),
]


def _rel(a, b):
    return np.max(np.abs(a - b) / np.maximum(np.abs(b), 1.0))


@pytest.fixture(scope="module", params=ARMS, ids=[a[0] for a in ARMS])
def case(request):
    name, kw, lockable = request.param
    arm = ft.load_arm(name, **kw)
    rng = np.random.default_rng(3)
    Q = np.array([arm.random_q(rng) for _ in range(60)])
    Js = batch.jacobians(arm, Q)
    xd = rng.normal(size=(len(Q), arm.m))
    return arm, Q, Js, xd, lockable


def test_jacobians_are_pinocchio_rows(case):
    """batch.jacobians stacks Arm.jacobian row by row."""
    arm, Q, Js, _, _ = case
    for q, J in zip(Q, Js, strict=True):
        np.testing.assert_allclose(J, arm.jacobian(q), atol=1e-14)


@pytest.mark.parametrize("name", ["lnva", "jvja"])
@pytest.mark.parametrize("chunk", [7, batch.CHUNK])
def test_resolve_jvj_rcn_equal_scalar(case, name, chunk):
    """resolve, jvj and rcn equal the scalar API within 1e-9 relative, for any chunk size."""
    arm, Q, Js, xd, lockable = case
    good = []
    for J in Js:
        try:
            ft.jvj(J, np.zeros(arm.m), np.zeros(arm.n), lockable)
            good.append(True)
        except IntolerableFailure:
            good.append(False)
    good = np.array(good)
    Js, xd = Js[good], xd[good]
    qd = batch.resolve(name, Js, xd, lockable, chunk=chunk)
    ref = np.array([ft.resolve(name, J, x, lockable) for J, x in zip(Js, xd, strict=True)])
    assert _rel(qd, ref) < 1e-9
    lam = batch.jvj(Js, xd, qd, lockable, chunk=chunk)
    lref = np.array([ft.jvj(J, x, v, lockable) for J, x, v in zip(Js, xd, ref, strict=True)])
    assert _rel(lam, lref) < 1e-9
    k = batch.rcn(Js, lockable, chunk=chunk)
    kref = np.array([ft.rcn(J, lockable) for J in Js])
    assert _rel(k, kref) < 1e-9


def test_multi_joint_weights_and_continuation():
    """Multi-joint scenarios, weights and the continuation response match the scalar API."""
    arm = ft.load_arm("panda", task="position")
    rng = np.random.default_rng(5)
    Q = np.array([arm.random_q(rng) for _ in range(20)])
    Js = batch.jacobians(arm, Q)
    xd = rng.normal(size=(20, 3))
    lock = [(0, 2), 3, (1, 5)]
    w = [1.0, 2.0, 0.5]
    for response in ("least_norm", "continuation"):
        qd = batch.resolve("jvja", Js, xd, lock, weights=w, response=response)
        ref = np.array(
            [
                ft.resolve("jvja", J, x, lock, weights=w, response=response)
                for J, x in zip(Js, xd, strict=True)
            ]
        )
        assert _rel(qd, ref) < 1e-9
        lam = batch.jvj(Js, xd, qd, lock, weights=w, response=response)
        lref = [
            ft.jvj(J, x, v, lock, weights=w, response=response)
            for J, x, v in zip(Js, xd, ref, strict=True)
        ]
        assert _rel(lam, np.array(lref)) < 1e-9


def test_mean_jump_is_the_direction_average():
    """mean_jump equals the average of JVJA's jump over many unit task directions."""
    arm = ft.load_arm("planar_3r")
    J = arm.jacobian(np.array([0.3, 1.1, -0.7]))
    phi = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    dirs = np.stack([np.cos(phi), np.sin(phi)], 1)
    lam = [ft.jvj(J, d, ft.resolve("jvja", J, d)) for d in dirs]
    np.testing.assert_allclose(batch.mean_jump(J[None])[0], np.mean(lam), rtol=1e-12)


def test_intolerable_rows_raise_or_nan():
    """An intolerable row raises by default and is NaN with intolerable='nan'."""
    arm = ft.load_arm("spatial_4r")
    Js = batch.jacobians(arm, np.array([[0.1, 0.4, 0.2, 1.0], [0.2, 0.3, 0.1, 0.9]]))
    xd = np.ones((2, 3))
    with pytest.raises(IntolerableFailure):
        batch.resolve("jvja", Js, xd, [3])
    assert np.all(np.isnan(batch.resolve("jvja", Js, xd, [3], intolerable="nan")))
    with pytest.raises(InvalidInput, match="intolerable"):
        batch.rcn(Js, [3], chunk=1) is None or batch.resolve("jvja", Js, xd, [3], intolerable="x")


def test_bad_input_is_refused():
    """Wrong shapes, unknown resolvers and non-finite input raise InvalidInput."""
    Js = np.ones((4, 2, 3))
    with pytest.raises(InvalidInput, match="xdots"):
        batch.resolve("lnva", Js, np.ones((3, 2)))
    with pytest.raises(InvalidInput, match="not one of"):
        batch.resolve("fastest", Js, np.ones((4, 2)))
    with pytest.raises(InvalidInput, match="needs the configuration"):
        batch.resolve("mda", Js, np.ones((4, 2)))
    with pytest.raises(InvalidInput, match="finite"):
        batch.rcn(np.full((2, 2, 3), np.nan))


def test_bench_has_the_batched_row(tmp_path, capsys):
    """fault-tolerance bench times the batched API against the loop and lists its target."""
    import json

    from fault_tolerance.bench import command as bench_command

    out = tmp_path / "b.json"
    args = ["--robots", "planar_3r", "--steps", "4", "--warmup", "1"]
    assert bench_command.main([*args, "--batch-configurations", "300", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "batched API" in text and "loop / batched API per configuration" in text
    data = json.loads(out.read_text())
    assert data["batch"]["configurations"] > 200 and data["batch"]["speedup"] > 0
    assert bench_command.main([*args, "--batch-configurations", "-1"]) == 2
