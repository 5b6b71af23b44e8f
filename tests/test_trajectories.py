"""Task paths: the paper's circles, CSV paths and callables."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.simulation.paths import CirclePath, FunctionPath, SampledPath, load_csv


def test_fig2_circle_velocity_matches_the_paper():
    """The Fig. 2 circle has ẋ = [0.2π sin 2πt, 0.2π cos 2πt] and starts at x0."""
    p = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 1.0)
    for t in np.linspace(0, 1, 7):
        np.testing.assert_allclose(
            p.xdot(t),
            [0.2 * np.pi * np.sin(2 * np.pi * t), 0.2 * np.pi * np.cos(2 * np.pi * t)],
            atol=1e-14,
        )
    np.testing.assert_allclose(p.x(0.0), [0.35, 0.0], atol=1e-15)
    np.testing.assert_allclose(p.x(1.0), [0.35, 0.0], atol=1e-14)


def test_powercube_circle_velocity_matches_the_paper():
    """The Sec. V path has ẋ = [−(π/30) sin(πt/3), (π/30) cos(πt/3)]."""
    p = CirclePath([0.5, 0.0], 0.1, np.pi / 3, 6.0, sign=-1.0)
    t = 1.3
    np.testing.assert_allclose(
        p.xdot(t),
        [-(np.pi / 30) * np.sin(np.pi * t / 3), (np.pi / 30) * np.cos(np.pi * t / 3)],
        atol=1e-14,
    )


def test_circle_position_is_the_integral_of_its_velocity():
    """x(t) − x(0) equals the trapezoidal integral of ẋ (4R path in rows y, z)."""
    p = CirclePath([0.09, 0.21, 0.27], 0.075, 2 * np.pi, 1.0, rows=(1, 2))
    ts = np.linspace(0, 0.7, 20001)
    v = np.array([p.xdot(t) for t in ts])
    integral = np.trapezoid(v, ts, axis=0)
    np.testing.assert_allclose(p.x(0.7) - p.x(0.0), integral, atol=1e-9)
    assert p.x(0.3)[0] == pytest.approx(0.09)


def test_csv_path_with_and_without_velocities(tmp_path):
    """A CSV path interpolates positions; velocities come from columns or by differentiation."""
    ts = np.linspace(0, 1, 201)
    x, y = 0.3 + 0.1 * ts**2, 0.2 * ts
    f = tmp_path / "p.csv"
    f.write_text("t,x,y\n" + "".join(f"{a},{b},{c}\n" for a, b, c in zip(ts, x, y, strict=True)))
    p = load_csv(f)
    assert p.duration == pytest.approx(1.0)
    np.testing.assert_allclose(p.x(0.5), [0.325, 0.1], atol=1e-6)
    np.testing.assert_allclose(p.xdot(0.5), [0.1, 0.2], atol=1e-3)
    g = tmp_path / "v.csv"
    g.write_text("t,x,y,vx,vy\n0,0,0,1,2\n1,1,2,1,2\n")
    np.testing.assert_allclose(load_csv(g).xdot(0.25), [1, 2])


@pytest.mark.parametrize(
    "text, match",
    [
        ("", "empty"),
        ("x,y\n0,0\n", "first column must be 't'"),
        ("t,x,y\n0,0,0\n", "at least 2"),
        ("t,x,y\n0,0,0\n1,a,0\n", ":3: a field is not a number"),
        ("t,x,y\n0,0,0\n1,0\n", ":3: 2 fields"),
        ("t,x,y\n0,0,0\n0,1,1\n", "increase strictly"),
    ],
)
def test_bad_csv_is_refused_with_the_line(tmp_path, text, match):
    """A malformed CSV path raises InvalidInput naming the file, line and problem."""
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(ft.InvalidInput, match=match):
        load_csv(f)


def test_function_path_differentiates_numerically():
    """A callable path without ẋ gets central differences of x(t)."""
    p = FunctionPath(lambda t: [np.sin(t), t**2], 2.0)
    np.testing.assert_allclose(p.xdot(0.7), [np.cos(0.7), 1.4], atol=1e-8)
    assert p.m == 2


def test_sampled_path_validates_shapes():
    """Sampled paths refuse mismatched shapes and non-finite values."""
    with pytest.raises(ft.InvalidInput):
        SampledPath(np.array([0.0, 1.0]), np.zeros((3, 2)))
    with pytest.raises(ft.InvalidInput):
        SampledPath(np.array([0.0, np.nan]), np.zeros((2, 2)))
