"""Figures a user can read: titles inside the figure, units on every axis and colour bar, one
colour per method in every figure and on the replay page, 3-D workspaces sliced through their
failure-tolerant region."""

from __future__ import annotations

import re

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.planning.posture import initial_posture
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.simulate import simulate

pytest.importorskip("matplotlib")
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402

from fault_tolerance.analysis.design.search import design  # noqa: E402
from fault_tolerance.analysis.workspace.closed_form import failure_tolerant_workspace  # noqa: E402
from fault_tolerance.analysis.workspace.result import Workspace  # noqa: E402
from fault_tolerance.figures import colors  # noqa: E402
from fault_tolerance.figures import runs as plots  # noqa: E402
from fault_tolerance.figures.design import design_figure  # noqa: E402
from fault_tolerance.figures.workspace import ftw_slices, workspace_figure  # noqa: E402
from fault_tolerance.resolution import registry  # noqa: E402
from fault_tolerance.viz.page import export_html  # noqa: E402

UNIT = re.compile(r"\[[^\]]+\]")
METHODS = ("lnva", "jvja", "mda", "jvja_inertia", "global")


@pytest.fixture(scope="module")
def runs():
    """Planar 3R, 0.4 s of the Fig. 2 circle with every method, a lock run and its planned run."""
    arm = ft.load_arm("planar_3r")
    q0 = initial_posture(arm, [0.35, 0.0]).q
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 0.4)
    every = {a: simulate(arm, path, a, q0=q0) for a in METHODS}
    lock = simulate(
        arm, path, "jvja", q0=q0, lock_joint="joint2", lock_time=0.2, feedback_gain=10.0
    )
    late = simulate(
        arm, path, "jvja", q0=q0, lock_joint="joint2", lock_time=0.3, feedback_gain=10.0
    )
    return arm, every, lock, late


@pytest.fixture(scope="module")
def spatial_ws():
    """The spatial 4R's workspace on a coarse grid (sampled)."""
    return failure_tolerant_workspace(
        ft.load_arm("spatial_4r"), grid=10, samples=3000, theta_samples=3
    )


@pytest.fixture(scope="module")
def figures(runs, spatial_ws):
    """Every kind of figure the commands write (simulate, lock, reproduce, workspace, design)."""
    _, every, lock, late = runs
    planar = failure_tolerant_workspace(
        ft.load_arm("planar_3r"), "-1:1,-2:2,-2:2", grid=41, samples=20
    )
    d = design(ft.load_arm("planar_3r"), objective="ftw-area", candidates=4, rounds=0, grid=31)
    long = "Figs. 9-10 — Power-Cube 3R, LNVA, joint 3 locks at the largest / smallest jump " * 2
    return {
        "comparison": plots.plot_comparison(every),
        "comparison, long title": plots.plot_comparison(every, long),
        "run": plots.plot_run(lock),
        "lock": plots.plot_lock({"joint2 locks at 0.2 s": lock}, planned=every["jvja"]),
        "two locks": plots.plot_lock({"early": lock, "late": late}, long, every["jvja"]),
        "workspace planar": workspace_figure(planar),
        "workspace spatial": workspace_figure(spatial_ws),
        "design": design_figure(d),
    }


def _drawn(fig):
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def _colorbar_axes(fig) -> list:
    return [ax for ax in fig.axes if getattr(ax, "_colorbar", None) is not None]


def test_titles_and_labels_lie_inside_the_figure(figures):
    """Suptitle, every axes title and axis label is drawn within the figure's box."""
    for name, fig in figures.items():
        renderer = _drawn(fig)
        texts = [fig._suptitle] if fig._suptitle is not None else []
        for ax in fig.axes:
            texts += [ax.title, ax._left_title, ax._right_title, ax.xaxis.label, ax.yaxis.label]
        box = fig.bbox
        for text in texts:
            if not text.get_text() or not text.get_visible():
                continue
            bb = text.get_window_extent(renderer)
            inside = (
                bb.x0 >= box.x0 - 0.5
                and bb.x1 <= box.x1 + 0.5
                and bb.y0 >= box.y0 - 0.5
                and bb.y1 <= box.y1 + 0.5
            )
            assert inside, f"{name}: {text.get_text()!r} at {bb} leaves the figure {box}"


def test_a_long_title_is_wrapped_not_clipped(figures):
    """The doubled Figs. 9-10 title is broken into lines (and, by the test above, fits)."""
    assert "\n" in figures["comparison, long title"]._suptitle.get_text()
    assert "\n" in figures["two locks"]._suptitle.get_text()


def test_every_axis_and_colour_bar_has_a_unit(figures):
    """Every shown axis is labelled with a unit in brackets; every colour bar too."""
    for name, fig in figures.items():
        bars = _colorbar_axes(fig)
        for ax in fig.axes:
            if ax in bars:
                cb = ax._colorbar
                label = cb.ax.get_ylabel() if cb.orientation == "vertical" else cb.ax.get_xlabel()
                assert UNIT.search(label), f"{name}: colour bar label {label!r} has no unit"
                continue
            if ax.xaxis.get_visible():
                assert UNIT.search(ax.get_xlabel()), f"{name}: x label {ax.get_xlabel()!r}"
            if ax.yaxis.get_visible():
                assert UNIT.search(ax.get_ylabel()), f"{name}: y label {ax.get_ylabel()!r}"
    assert _colorbar_axes(figures["workspace spatial"]), "the workspace maps have colour bars"


def _figure_colours(figures) -> tuple[dict[str, set[str]], set[str]]:
    """``({method: colours of its curves}, joint colours)`` from the figures' lines."""
    from matplotlib.colors import to_hex

    methods: dict[str, set[str]] = {}
    joints: set[str] = set()
    for fig in figures.values():
        for ax in fig.axes:
            for line in ax.get_lines():
                gid = line.get_gid() or ""
                kind, _, who = gid.partition(":")
                if kind == "method":
                    methods.setdefault(who, set()).add(to_hex(line.get_color()))
                elif kind == "joint":
                    joints.add(to_hex(line.get_color()))
    return methods, joints


def _page_colours(html: str) -> tuple[dict[str, set[str]], set[str]]:
    """``({method: colours}, joint colours)`` of the replay page: its keys and its curves."""
    methods: dict[str, set[str]] = {}
    for m, c in re.findall(
        r'class="ft-key" data-run="\d+" data-method="([^"]*)" data-color="([^"]*)"', html
    ):
        methods.setdefault(m, set()).add(c.lower())
    runs = dict(re.findall(r'data-run="(\d+)" data-method="([^"]*)"', html))
    for i, stroke in re.findall(
        r'<g class="ft-run" data-run="(\d+)"><polyline[^>]*stroke="([^"]+)"', html
    ):
        methods.setdefault(runs[i], set()).add(stroke.lower())
    joints = {c.lower() for c in re.findall(r'data-joint="[^"]*" data-color="([^"]+)"', html)}
    joints |= {
        c.lower() for c in re.findall(r'<polyline[^>]*stroke="([^"]+)"[^>]*data-joint=', html)
    }
    return methods, joints


@pytest.fixture(scope="module")
def page(runs, tmp_path_factory) -> str:
    """The replay page of a folder holding a run of every method (as `simulate --out` writes)."""
    _, every, _, _ = runs
    out = tmp_path_factory.mktemp("every")
    for alg, run in every.items():
        run.save(out / alg)
    return export_html(out, out / "every.html").read_text(encoding="utf-8")


def test_one_colour_per_method_in_every_figure_and_the_page(figures, page):
    """Each method has one colour across figures and page; methods differ; no joint has one."""
    fm, fj = _figure_colours(figures)
    pm, pj = _page_colours(page)
    assert set(METHODS) <= set(fm) and set(METHODS) <= set(pm), (sorted(fm), sorted(pm))
    assert fj and pj, "the joints' curves are found"
    every = {m: fm.get(m, set()) | pm.get(m, set()) for m in set(fm) | set(pm)}
    for m, cs in every.items():
        assert len(cs) == 1, f"{m} is drawn in {sorted(cs)}"
        assert cs == {colors.method_colour(m)}
    used = [next(iter(cs)) for cs in every.values()]
    assert len(set(used)) == len(used), every
    assert not set(used) & (fj | pj), (every, fj | pj)


def test_a_second_run_of_a_method_keeps_its_colour_and_is_dashed(figures):
    """The two lock runs (both JVJA) share JVJA's red; the second one is dashed."""
    ax = figures["two locks"].axes[1]
    lines = [ln for ln in ax.get_lines() if (ln.get_gid() or "") == "method:jvja"]
    assert [ln.get_linestyle() for ln in lines] == ["-", "--"]
    assert {ln.get_color() for ln in lines} == {colors.method_colour("jvja")}


def test_a_users_resolver_gets_a_colour_of_its_own():
    """A resolver registered with the default grey (a joint colour) gets a spare method colour."""
    jvja = registry.get("jvja")
    entry = registry.ResolverEntry("grey_jvja", jvja.rates, jvja.options)
    registry.register(entry)
    try:
        c = colors.method_colour("grey_jvja")
        others = {m: v for m, v in colors.method_colours().items() if m != "grey_jvja"}
        assert entry.colour in colors.JOINT_COLOURS and c not in colors.JOINT_COLOURS
        assert c not in others.values()
    finally:
        registry.unregister("grey_jvja")


def _synthetic(ftw_z: int) -> Workspace:
    """A 3-D grid whose FTW is a small cube around z index ``ftw_z``, W(A) a larger slab."""
    n = 12
    axis = np.linspace(-0.55, 0.55, n)  # [m], step 0.1
    pre = np.zeros((n, n, n), bool)
    pre[2:10, 2:10, 1:11] = True
    ftw = np.zeros_like(pre)
    ftw[3:6, 4:8, ftw_z - 1 : ftw_z + 2] = True  # 3 x 4 cells on three z planes
    ftw[3:7, 4:8, ftw_z] = True  # the largest FTW plane is z index ftw_z: 4 x 4 cells
    maps = np.where(pre, 1.0, np.nan)
    spec = {"robot": {"source": "cube"}, "lockable": ["joint1"]}
    return Workspace(spec, (axis, axis, axis), pre, ftw, ftw[None], maps, maps, 1e-3, "", "")


def test_spatial_slices_pass_through_the_ftw_and_say_where():
    """The z plane is the one with the largest FTW area; its title names it and that area."""
    ws = _synthetic(ftw_z=8)
    z, y, x = ftw_slices(ws)
    assert (z.axis, z.cell) == (2, 8)
    np.testing.assert_allclose(z.area_ftw, 16 * 0.01, atol=1e-12)  # 16 cells of 0.1 m x 0.1 m
    assert ws.ftw[z.select()].sum() == 16 and ws.ftw[y.select()].any() and ws.ftw[x.select()].any()
    fig = workspace_figure(ws)
    title = fig.axes[0].get_title()
    assert f"z = {ws.axes[2][8]:.3f} m" in title and "FTW 0.16 m² (dark)" in title, title


def test_the_spatial_4r_is_sliced_through_its_ftw(spatial_ws):
    """On the 4R every chosen plane holds the largest FTW area of its axis (and some FTW)."""
    assert spatial_ws.size_ftw > 0
    for s in ftw_slices(spatial_ws):
        other = tuple(k for k in range(3) if k != s.axis)
        counts = spatial_ws.ftw.sum(axis=other)
        assert counts[s.cell] == counts.max() > 0


def test_a_workspace_without_ftw_says_so():
    """No FTW at all: the planes with the largest W(A), titled so."""
    ws = _synthetic(ftw_z=8)
    empty = Workspace(ws.spec, ws.axes, ws.pre, np.zeros_like(ws.ftw), ws.locks, ws.jump, ws.rcn,
                      ws.cell, "", "")  # fmt: skip
    assert all(s.area_ftw == 0 and s.area_pre > 0 for s in ftw_slices(empty))
    assert "no FTW" in workspace_figure(empty).axes[0].get_title()


def test_joint_palette_never_meets_a_method_colour():
    """The joint palette and every registered method's colour are disjoint sets of colours."""
    assert not set(colors.JOINT_COLOURS) & set(colors.method_colours().values())


def test_plane_areas_add_up_to_the_volume(spatial_ws):
    """(FW1): the plane areas of an axis times its grid step sum to the FTW and W(A) volumes."""
    from fault_tolerance.figures.workspace import slice_areas

    for axis in range(3):
        step = float(spatial_ws.axes[axis][1] - spatial_ws.axes[axis][0])
        for mask, size in (
            (spatial_ws.ftw, spatial_ws.size_ftw),
            (spatial_ws.pre, spatial_ws.size_pre),
        ):
            areas = slice_areas(mask, axis, spatial_ws.cell, step)
            np.testing.assert_allclose(areas.sum() * step, size, rtol=1e-12, atol=1e-15)
