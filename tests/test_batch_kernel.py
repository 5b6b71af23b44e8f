"""batch.resolve / rcn on the compiled kernels equal their stacked NumPy paths and ft.resolve."""

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.analysis import batch
from fault_tolerance.analysis.fast import batch as batch_kernel
from fault_tolerance.errors import IntolerableFailure, InvalidInput
from fault_tolerance.resolution.scenarios import scenarios

pytest.importorskip("numba")

ARMS = [
    ("planar_3r", {}, [0, 1, 2]),
    ("panda", {"task": "position"}, [0, 1, 2, 3, 4]),
    ("panda", {}, [0, 2, 4, 6]),
    ("ur5", {"task": "position"}, [0, 1, 2]),
]


def _rel(a, b):
    return np.max(np.abs(a - b) / np.maximum(np.abs(b), 1.0))


def _rows(arm, rng, size, near=0):
    """Random configurations, and ``near`` of them pushed to a singularity of J (scaled columns)."""
    Q = np.array([arm.random_q(rng) for _ in range(size)])
    Js = batch.jacobians(arm, Q)
    for b in range(near):  # σ_min of J around SIGMA_EPS: certified, refused, damped
        U, s, Vt = np.linalg.svd(Js[b], full_matrices=False)
        s[-1] = 1e-3 * 10.0 ** rng.uniform(-2, 1)
        Js[b] = (U * s) @ Vt
    return Js, rng.normal(size=(size, arm.m))


def _scalar(name, Js, xd, lockable, **kw):
    out = []
    for J, x in zip(Js, xd, strict=True):
        try:
            out.append(ft.resolve(name, J, x, lockable, **kw))
        except IntolerableFailure:
            out.append(np.full(J.shape[1], np.nan))
    return np.array(out)


@pytest.fixture(scope="module", params=ARMS, ids=["planar_3r", "panda_pos", "panda_pose", "ur5"])
def case(request):
    name, kw, lockable = request.param
    arm = ft.load_arm(name, **kw)
    Js, xd = _rows(arm, np.random.default_rng(11), 80, near=20)
    return arm, Js, xd, lockable


@pytest.mark.parametrize("name", ["lnva", "jvja"])
def test_compiled_equals_stacked_and_scalar(case, name):
    """Random and near-singular rows: compiled = stacked NumPy within 1e-9, and = ft.resolve.

    Rows the kernel keeps equal ft.resolve within 1e-9; the refused rows are the stacked path's
    own (which differs from ft.resolve by up to ~1e-8 on a few ill-conditioned Panda pose rows).
    """
    arm, Js, xd, lockable = case
    qd = batch.resolve(name, Js, xd, lockable, intolerable="nan")
    ref = batch.resolve_stacked(name, Js, xd, lockable, intolerable="nan")
    np.testing.assert_array_equal(np.isnan(qd), np.isnan(ref))
    ok = np.isfinite(ref).all(axis=1)
    assert ok.sum() > 40
    assert _rel(qd[ok], ref[ok]) < 1e-9
    sc = scenarios(lockable, arm.n, r=arm.redundancy) if name == "jvja" else None
    kept = batch_kernel.rates(Js, xd, sc)[1] == 0
    assert kept.sum() >= 10
    np.testing.assert_array_equal(qd[~kept & ok], ref[~kept & ok])
    assert _rel(qd[kept], _scalar(name, Js, xd, lockable)[kept]) < 1e-9


def test_near_singular_rows_are_refused_and_redone():
    """Rows without a certificate get status 1 and the stacked path's damped rates exactly."""
    arm = ft.load_arm("panda", task="position")
    Js, xd = _rows(arm, np.random.default_rng(2), 30, near=30)
    sc = scenarios([0, 1, 2, 3, 4], arm.n, r=arm.redundancy)
    _, status = batch_kernel.rates(Js, xd, sc)
    refused = np.flatnonzero(status)
    assert 0 < refused.size < 30
    qd = batch.resolve("jvja", Js, xd, [0, 1, 2, 3, 4], intolerable="nan")
    lock = [0, 1, 2, 3, 4]
    ref = batch.resolve_stacked("jvja", Js[refused], xd[refused], lock, intolerable="nan")
    np.testing.assert_array_equal(qd[refused], ref)
    ok = np.isfinite(ref).all(axis=1)
    assert _rel(ref[ok], _scalar("jvja", Js[refused], xd[refused], [0, 1, 2, 3, 4])[ok]) < 1e-9


def test_intolerable_rows_raise_or_nan_as_the_stacked_path():
    """A pivot of N below the kernel's threshold: status 2; NaN or IntolerableFailure as before."""
    arm = ft.load_arm("spatial_4r")
    Q = np.array([[0.1, 0.4, 0.2, 1.0], [0.2, 0.3, 0.1, 0.9], [0.3, 1.0, -0.5, 0.4]])
    Js, xd = batch.jacobians(arm, Q), np.ones((3, 3))
    _, status = batch_kernel.rates(Js, xd, scenarios([3], 4, r=1))
    assert status[:2].tolist() == [2, 2]
    qd = batch.resolve("jvja", Js, xd, [3], intolerable="nan")
    np.testing.assert_array_equal(qd, batch.resolve_stacked("jvja", Js, xd, [3], intolerable="nan"))
    assert np.isnan(qd[:2]).all()
    for fn in (batch.resolve, batch.resolve_stacked):
        with pytest.raises(IntolerableFailure) as err:
            fn("jvja", Js, xd, [3])
        assert "3" in str(err.value) or "joint" in str(err.value)


@pytest.mark.parametrize("lock,w", [([0, 2, 5], [1.0, 3.0, 0.5]), ([(0, 2), 3, (1, 5)], None),
                                    ([(0, 2), 3, (1, 5)], [1.0, 2.0, 0.5])])  # fmt: skip
def test_weights_and_multi_joint(lock, w):
    """Weights (compiled) and multi-joint scenarios (stacked) equal the stacked path, ft.resolve."""
    arm = ft.load_arm("panda", task="position")
    Js, xd = _rows(arm, np.random.default_rng(5), 60, near=10)
    qd = batch.resolve("jvja", Js, xd, lock, weights=w, intolerable="nan")
    ref = batch.resolve_stacked("jvja", Js, xd, lock, weights=w, intolerable="nan")
    np.testing.assert_array_equal(np.isnan(qd), np.isnan(ref))
    ok = np.isfinite(ref).all(axis=1)
    assert ok.sum() > 30
    assert _rel(qd[ok], ref[ok]) < 1e-9
    assert _rel(qd[ok], _scalar("jvja", Js, xd, lock, weights=w)[ok]) < 1e-9


def test_huge_weights_do_not_overflow():
    """Weights whose sum overflows: both paths give ft.resolve's rates (weights over the max)."""
    arm = ft.load_arm("panda", task="position")
    Js, xd = _rows(arm, np.random.default_rng(8), 10)
    w = [1e308, 1e308, 5e307]
    qd = batch.resolve("jvja", Js, xd, [0, 2, 5], weights=w)
    ref = batch.resolve_stacked("jvja", Js, xd, [0, 2, 5], weights=w)
    assert _rel(qd, ref) < 1e-9
    assert _rel(qd, _scalar("jvja", Js, xd, [0, 2, 5], weights=w)) < 1e-9
    assert not np.allclose(qd, batch.resolve("lnva", Js, xd))


def test_continuation_and_other_layouts_take_the_stacked_path():
    """response='continuation', Fortran-ordered and read-only input give the stacked results."""
    arm = ft.load_arm("panda", task="position")
    Js, xd = _rows(arm, np.random.default_rng(6), 20)
    ref = batch.resolve_stacked("jvja", Js, xd, [0, 1, 2], response="continuation")
    cont = batch.resolve("jvja", Js, xd, [0, 1, 2], response="continuation")
    np.testing.assert_array_equal(cont, ref)
    F = np.asfortranarray(Js)
    F.flags.writeable = False
    same = batch.resolve("jvja", Js, xd, [0, 1, 2])
    assert _rel(batch.resolve("jvja", F, xd, [0, 1, 2]), same) == 0


def test_errors_unchanged():
    """Both entry points refuse bad input with the same InvalidInput messages."""
    Js = np.ones((4, 2, 3))
    for fn in (batch.resolve, batch.resolve_stacked):
        with pytest.raises(InvalidInput, match="xdots"):
            fn("lnva", Js, np.ones((3, 2)))
        with pytest.raises(InvalidInput, match="not one of"):
            fn("fastest", Js, np.ones((4, 2)))
        with pytest.raises(InvalidInput, match="intolerable"):
            fn("jvja", Js, np.ones((4, 2)), intolerable="x")
        with pytest.raises(InvalidInput, match="finite"):
            fn("jvja", np.full((4, 2, 3), np.nan), np.ones((4, 2)))
    assert batch.resolve("jvja", np.ones((0, 2, 3)), np.ones((0, 2))).shape == (0, 3)
    with pytest.raises(InvalidInput, match="needs the configuration"):  # MDA: no arm, no q
        batch.resolve("mda", Js, np.ones((4, 2)))
    with pytest.raises(InvalidInput, match="not one of"):  # the stacked code is LNVA and JVJA's
        batch.resolve_stacked("mda", Js, np.ones((4, 2)))


def test_kernel_runs_as_plain_python():
    """The row loop without numba (py_func) gives the compiled statuses and rates."""
    arm = ft.load_arm("planar_3r")
    Js, xd = _rows(arm, np.random.default_rng(1), 6, near=2)
    sc = scenarios([0, 1, 2], 3, r=1)
    out, status = batch_kernel.rates(Js, xd, sc)
    out2, status2 = np.empty_like(out), np.empty_like(status)
    ws = batch_kernel.single_workspace(sc, 2, 3)
    batch_kernel.single_rows.py_func(Js, xd, out2, status2, ws, 1, np.empty((2, 2)), np.empty(2))
    np.testing.assert_array_equal(status, status2)
    ok = status == 0
    assert _rel(out[ok], out2[ok]) < 1e-12


@pytest.mark.parametrize("which", [0, 1, 3])
def test_rcn_compiled_equals_stacked_and_scalar(which):
    """Compiled k_S (rank-one eigen) = stacked eigvalsh = ft.rcn within 1e-9; large k redone."""
    name, kw, lockable = ARMS[which]
    arm = ft.load_arm(name, **kw)
    Js, _ = _rows(arm, np.random.default_rng(4), 120, near=30)
    k = batch.rcn(Js, lockable)
    ref = batch.rcn_stacked(Js, lockable)
    assert _rel(k, ref) < 1e-9
    assert _rel(k, np.array([ft.rcn(J, lockable) for J in Js])) < 1e-9
    sc = scenarios(lockable, arm.n, r=arm.redundancy)
    _, status = batch_kernel.reduced_condition_numbers(Js, sc)
    assert 0 < status.sum() < len(Js)
    np.testing.assert_array_equal(k[status != 0], ref[status != 0])
    K = batch.square_sum_rcn(Js, lockable)
    assert _rel(K, np.einsum("bf,bf->b", ref, ref)) < 1e-9


def test_rcn_multi_joint_and_degenerate_rows_take_the_stacked_path():
    """Multi-joint scenarios and a zero Jacobian row give the stacked results exactly."""
    arm = ft.load_arm("panda", task="position")
    Js, _ = _rows(arm, np.random.default_rng(9), 10)
    lock = [(0, 2), 3]
    np.testing.assert_array_equal(batch.rcn(Js, lock), batch.rcn_stacked(Js, lock))
    Js[3] = 0.0
    np.testing.assert_array_equal(batch.rcn(Js, [0, 1])[3], batch.rcn_stacked(Js, [0, 1])[3])
