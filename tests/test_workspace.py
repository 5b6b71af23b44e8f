"""Failure-tolerant workspace: brute force, zero area, scaling, workers, resume."""

import os
import re

import dask
import numpy as np
import pytest
from conftest import ROOT
from scipy.optimize import least_squares

import fault_tolerance as ft
from fault_tolerance.analysis import sweep
from fault_tolerance.analysis.workspace.closed_form import (
    failure_tolerant_workspace,
    planar_chunk,
    radius_layout,
    workspace_spec,
)
from fault_tolerance.errors import InvalidInput


def scaled_urdf(tmp_path, factor, limit=3.14159, name="planar_3r.urdf"):
    """planar_3r.urdf with every origin scaled by ``factor`` and joint limits ±``limit``."""
    text = (ROOT / "robots" / name).read_text()

    def scale(m):
        xyz = [float(v) * factor for v in m.group(1).split()]
        return 'xyz="' + " ".join(repr(v) for v in xyz) + '"'

    text = re.sub(r'xyz="([^"]+)"', scale, text)
    text = re.sub(r'(<axis) xyz="[^"]+"', r'\1 xyz="0 0 1"', text)
    text = text.replace('lower="-3.14159" upper="3.14159"', f'lower="{-limit}" upper="{limit}"')
    path = tmp_path / f"scaled_{factor}_{limit}.urdf"
    path.write_text(text)
    return path


class _Brute:
    """Numerical IK on Pinocchio's FK: bounded least squares from the nearest of a joint grid."""

    def __init__(self, arm, lo, hi, fixed=None, per_axis=25):
        self.arm, self.lo, self.hi, self.fixed = arm, lo, hi, fixed
        self.free = [j for j in range(arm.n) if fixed is None or j != fixed[0]]
        axes = [np.linspace(lo[j], hi[j], per_axis) for j in self.free]
        self.U = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(self.free))
        self.X = np.array([arm.fk(self._q(u)) for u in self.U])

    def _q(self, u):
        q = np.empty(self.arm.n)
        q[self.free] = u
        if self.fixed is not None:
            q[self.fixed[0]] = self.fixed[1]
        return q

    def reach(self, p, starts=4):
        lo, hi = self.lo[self.free], self.hi[self.free]
        near = np.argsort(np.linalg.norm(self.X - p, axis=1))[:starts]
        for u0 in self.U[near]:
            r = least_squares(
                lambda u: self.arm.fk(self._q(u)) - p,
                np.clip(u0, lo + 1e-9, hi - 1e-9),
                bounds=(lo, hi),
                xtol=1e-13,
                ftol=1e-13,
                gtol=1e-13,
            )
            if np.linalg.norm(r.fun) < 1e-7:
                return True
        return False


@pytest.mark.slow
@pytest.mark.parametrize("physical", [None, 2.6])
def test_brute_force_equals_map(tmp_path, physical):
    """On a tiny grid, numerical IK before and after every lock (at many angles) equals the map."""
    arm = (
        ft.load_arm("powercube_3r")
        if physical is None
        else ft.load_arm(str(scaled_urdf(tmp_path, 1.0, physical)), tip="tool", task="planar")
    )
    lim = np.array([[-1.0, 1.0], [-2.0, 2.0], [-2.4, 2.4]])
    ws = failure_tolerant_workspace(arm, lim, grid=5, samples=400, theta_samples=401)
    phys = np.stack([arm.lower, arm.upper], 1)
    pre = _Brute(arm, lim[:, 0], lim[:, 1], per_axis=15)
    locks = [
        [_Brute(arm, phys[:, 0], phys[:, 1], (i, t)) for t in np.linspace(*lim[i], 13)]
        for i in range(3)
    ]
    x, y = ws.axes
    for a in range(5):
        for b in range(5):
            p = np.array([x[a], y[b]])
            assert pre.reach(p) == ws.pre[a, b], p
            for i in range(3):
                ok = all(br.reach(p) for br in locks[i])
                assert ok == ws.locks[i, a, b], (p, i)
    assert 0 < ws.pre.sum() < ws.pre.size and 0 < ws.locks.sum() < ws.locks.size  # not trivial


def test_equal_links_without_limits_have_zero_area():
    """Equal links, no artificial limits: the FTW is the circle of radius one link (area 0)."""
    ws = failure_tolerant_workspace(ft.load_arm("planar_3r"), grid=101, samples=16)
    assert ws.area_ftw == 0.0
    assert abs(ws.area_pre - np.pi * 1.5**2) < 0.1
    # joint 1 alone: the disc of radius l2 + l3 - l1 = 0.5 survives every lock angle
    assert abs((ws.pre & ws.locks[0]).sum() * ws.cell - np.pi * 0.25) < 0.03


def test_areas_scale_with_the_square_of_the_link_length(tmp_path):
    """A URDF with every length doubled has four times the areas, cell for cell."""
    lim = "-1.2:1.2,-2:2,-2.5:2.5"
    opts = dict(grid=61, samples=40)
    a = failure_tolerant_workspace(ft.load_arm("planar_3r"), lim, **opts)
    big = ft.load_arm(str(scaled_urdf(tmp_path, 2.0)), tip="tool", task="planar")
    b = failure_tolerant_workspace(big, lim, **opts)
    assert a.area_ftw > 0
    np.testing.assert_array_equal(a.ftw, b.ftw)
    np.testing.assert_allclose(
        [b.area_pre, b.area_ftw], [4 * a.area_pre, 4 * a.area_ftw], rtol=1e-12
    )


def test_maps_are_minima_over_the_self_motion():
    """The jump and K maps are finite exactly on W(A), and K >= f (each k_S >= 1)."""
    ws = failure_tolerant_workspace(ft.load_arm("planar_3r"), "-2:2,-2:2,-2:2", grid=41, samples=30)
    assert np.all(np.isnan(ws.rcn[~ws.pre]))
    fin = np.isfinite(ws.rcn)
    assert fin[ws.pre].mean() > 0.95
    assert np.all(ws.rcn[fin] >= 3.0)
    assert np.all(ws.jump[np.isfinite(ws.jump)] > 0)


def _equal(a, b):
    np.testing.assert_array_equal(a.pre, b.pre)
    np.testing.assert_array_equal(a.ftw, b.ftw)
    np.testing.assert_array_equal(a.locks, b.locks)
    np.testing.assert_array_equal(a.jump, b.jump)
    np.testing.assert_array_equal(a.rcn, b.rcn)


@pytest.mark.slow
def test_serial_one_and_two_workers_are_identical(tmp_path):
    """Serial, one in-process worker and a two-process LocalCluster give identical numbers."""
    arm = ft.load_arm("planar_3r")
    opts = dict(grid=41, samples=24, chunks=6)
    serial = failure_tolerant_workspace(arm, "-1:1,-2:2,-2:2", **opts)
    one = failure_tolerant_workspace(arm, "-1:1,-2:2,-2:2", workers=1, **opts)
    two = failure_tolerant_workspace(arm, "-1:1,-2:2,-2:2", workers=2, **opts)
    _equal(serial, one)
    _equal(serial, two)
    sp = ft.load_arm("spatial_4r")
    s1 = failure_tolerant_workspace(sp, grid=8, samples=3000, theta_samples=3)
    s2 = failure_tolerant_workspace(sp, grid=8, samples=3000, theta_samples=3, workers=2)
    _equal(s1, s2)
    assert 0 < s1.size_ftw < s1.size_pre


@pytest.mark.slow
def test_local_cluster_listens_on_loopback_only():
    """The embedded two-worker cluster's scheduler and HTTP server bind 127.0.0.1."""
    client = sweep.client_for(2, None)
    try:
        assert client.scheduler.address.startswith("tcp://127.0.0.1:")
        assert client.dashboard_link.startswith("http://127.0.0.1:")
        workers = client.scheduler_info()["workers"]
        assert len(workers) == 2 and all(w.startswith("tcp://127.0.0.1:") for w in workers)
        # one BLAS / OpenMP / numba thread per worker, and no MALLOC_TRIM_THRESHOLD_ (which turns
        # off glibc's adaptive mmap threshold: a page fault per fresh page of every temporary)
        names = ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                 "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")  # fmt: skip
        env = client.run(lambda: [os.environ.get(n) for n in names])
        assert list(env.values()) == [[None, "1", "1", "1", "1"]] * 2, env
        profile = client.run(lambda: dask.config.get("distributed.worker.profile.enabled"))
        assert list(profile.values()) == [False, False]  # no 10 ms stack sampling of the task
    finally:
        cluster = client.cluster
        client.close()
        cluster.close()


@pytest.mark.parametrize("grid, chunks", [(801, 32), (201, 16), (40, 6), (3, 16)])
def test_chunks_hold_every_radius_once_and_share_them_evenly(grid, chunks):
    """Each point inside the reach is in one chunk; a radius is never split; chunks get nearly
    equal numbers of radii (their cost) and of points, from the whole range of radii."""
    order, keys, chunk = radius_layout(grid, chunks)
    i = 2 * np.arange(grid) - (grid - 1)
    assert np.array_equal(
        np.sort(order), np.flatnonzero((i[:, None] ** 2 + i[None, :] ** 2).ravel() <= grid**2)
    )
    radii = [np.unique(keys[chunk == k]) for k in range(chunks)]
    assert sum(len(r) for r in radii) == len(np.unique(keys))  # no radius in two chunks
    counts = np.array([len(r) for r in radii])
    assert counts.max() - counts.min() <= 1
    if grid >= 201:
        points = np.bincount(chunk, minlength=chunks)
        assert points.max() < 1.2 * points.min()
        assert all(r[0] < keys[len(keys) // 10] and r[-1] > keys[-len(keys) // 10] for r in radii)


def test_chunks_are_kept_and_resumed(tmp_path, monkeypatch):
    """Finished chunks are written; an interrupted run keeps them and a rerun resumes from them."""
    arm = ft.load_arm("planar_3r")
    opts = dict(grid=21, samples=12, chunks=4)
    calls = []
    interrupt = [True]

    def flaky(spec, k):
        calls.append(k)
        if k == 2 and interrupt[0]:
            raise KeyboardInterrupt
        return planar_chunk(spec, k)

    spec = workspace_spec(arm, "-1:1,-2:2,-2:2", **opts)
    with pytest.raises(KeyboardInterrupt):
        sweep.run(flaky, spec, 4, folder=tmp_path)
    folder = sweep.chunk_folder(tmp_path, spec)
    assert sorted(p.name for p in folder.glob("chunk-*.npz")) == [
        "chunk-00000.npz",
        "chunk-00001.npz",
    ]
    calls.clear()
    interrupt[0] = False
    chunks = sweep.run(flaky, spec, 4, folder=tmp_path)
    assert calls == [2, 3]
    ref = sweep.run(planar_chunk, spec, 4)
    for c, r in zip(chunks, ref, strict=True):
        for key in r:
            np.testing.assert_array_equal(c[key], r[key])
    assert not list(folder.glob(".tmp-*"))


def test_bad_input_is_refused():
    """Limits outside the physical range, wrong counts, pose tasks and unknown options raise."""
    arm = ft.load_arm("planar_3r")
    with pytest.raises(InvalidInput, match="physical"):
        workspace_spec(arm, "-4:1,-1:1,-1:1")
    with pytest.raises(InvalidInput, match="one lo:hi pair per joint"):
        workspace_spec(arm, "-1:1")
    with pytest.raises(InvalidInput, match="unknown"):
        workspace_spec(arm, None, bogus=3)
    with pytest.raises(InvalidInput, match="position task"):
        workspace_spec(ft.load_arm("panda", task="pose"))
    with pytest.raises(InvalidInput, match="workers"):
        sweep.run(planar_chunk, {}, 0, workers=-1)
