"""Replay of runs in the browser with meshcat: live, or as one self-contained HTML file.

A run is replayed as a meshcat **animation** (the viewer's *Animations* controls play, pause and
scrub it), recorded frame by frame from the run's joint positions with Pinocchio's
``MeshcatVisualizer``: real time by default, ``speed`` times faster otherwise, ``fps`` frames per
second of replay (a 1 kHz run is decimated; meshcat interpolates between frames). The scene adds

* the desired path (dark line) and the tool's actual trace (teal line), as thin tubes so they keep
  their width on every screen;
* a small dark ball that moves along the desired path, so the path error after a lock shows;
* for a lock run, the link driven by the locked joint turns magenta from the lock time on, and a
  magenta ball marks the lock moment on the path.

Two outputs:

* :func:`export_html` writes one HTML file that plays offline: meshcat's viewer (three.js
  included) and the scene's commands are inlined; nothing is fetched from a network or a server.
* :func:`serve` starts meshcat's server in a child process, bound to ``127.0.0.1`` only (meshcat's
  own server listens on every interface for its web port; ours does not), sends it the scene and
  returns the URL and a handle whose ``close()`` stops the server.

meshcat is imported lazily, so ``import fault_tolerance`` does not import it.

In the page, ``window.viewer`` is meshcat's viewer; ``viewer.animator`` holds the animation
(``play()``, ``pause()``, ``seek(t)``, ``time_scrubber``, ``duration``, with ``t`` in replay
seconds). The exported page also sets ``window.ftReplay`` (robot, speed, lock time, ready flag).
"""

from __future__ import annotations

import atexit
import base64
import contextlib
import html as html_lib
import io
import json
import math
import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, NamedTuple

import numpy as np
import pinocchio as pin

from .arm import Arm, arm_from_meta
from .errors import FaultToleranceError, InvalidInput
from .simulation import Run, write_atomic

#: The only interface the live server listens on.
LOCALHOST = "127.0.0.1"

# Colours (RGB in [0, 1]), chosen apart in hue from the shipped arms' red, orange, green, blue and
# yellow links so a reader (and the browser test) can tell them apart.
LOCK_COLOR = (0.86, 0.10, 0.86)  # magenta: the locked joint's link and the lock moment
TRACE_COLOR = (0.0, 0.70, 0.74)  # teal: the tool's actual trace
PATH_COLOR = (0.13, 0.14, 0.18)  # near black: the desired path and the moving target
BACKGROUND = ((0.98, 0.98, 0.99), (0.80, 0.82, 0.86))  # top, bottom

#: Largest number of points of a drawn path (longer runs are decimated for the tube meshes).
PATH_POINTS = 300
#: Sides of the tubes drawn for the paths.
TUBE_SIDES = 8
#: Vertical field of view of meshcat's default camera [deg].
CAMERA_FOV = 75.0


def _require_meshcat():
    """Import meshcat, or raise an ImportError that says what to install."""
    import warnings

    try:
        with warnings.catch_warnings():  # meshcat 0.3 imports pyzmq's deprecated eventloop module
            warnings.simplefilter("ignore", DeprecationWarning)
            import meshcat  # noqa: F401
            import meshcat.geometry  # noqa: F401
            import umsgpack  # noqa: F401  (a dependency of meshcat)
    except ImportError as err:
        raise ImportError(
            "the meshcat replay needs the 'meshcat' package (>= 0.3.2): "
            "pip install 'meshcat>=0.3.2'"
        ) from err
    import meshcat

    return meshcat


# -- what is replayed -----------------------------------------------------------------------


@dataclass
class _Motion:
    """Joint positions over time and what to draw with them."""

    t: np.ndarray  # [s], shape (K,)
    q: np.ndarray  # [rad], shape (K, n)
    x_des: np.ndarray | None  # desired task position, shape (K, m)
    lock: dict | None  # {"joint", "index", "time"}
    meta: dict = field(default_factory=dict)


def _load_motion(run, arm: Arm | None, dt: float | None) -> tuple[_Motion, Arm]:
    """A :class:`_Motion` and its arm from a Run, a run folder, an array of q or a pair (t, q)."""
    if isinstance(run, (str, Path)):
        run = Run.load(run)
    if isinstance(run, Run):
        if arm is None:
            arm = arm_from_meta(run.meta)
        motion = _Motion(
            np.asarray(run.t, dtype=float),
            np.asarray(run.q, dtype=float),
            np.asarray(run.x_des, dtype=float),
            run.meta.get("lock"),
            dict(run.meta),
        )
        names = run.meta.get("joint_names")
        if names and list(names) != list(arm.joint_names):
            raise InvalidInput(
                f"the run was made with joints {list(names)}, the arm has {arm.joint_names}; "
                "pass the arm the run was made with"
            )
    else:
        if arm is None:
            raise InvalidInput("replaying an array of joint positions needs the arm (arm=...)")
        if isinstance(run, tuple) and len(run) == 2:
            t, q = (np.asarray(a, dtype=float) for a in run)
        else:
            q = np.asarray(run, dtype=float)
            if dt is None or not (np.isfinite(dt) and dt > 0):
                raise InvalidInput(
                    f"an array of joint positions needs a time step dt > 0, got {dt}"
                )
            t = np.arange(len(q)) * float(dt)
        if q.ndim != 2 or t.shape != (len(q),) or len(q) < 1:
            raise InvalidInput(
                f"q must have shape (K, n) with K times; got q {q.shape}, t {t.shape}"
            )
        motion = _Motion(t, q, None, None, {"robot": arm.name})
    if motion.q.ndim != 2 or motion.q.shape[1] != arm.n:
        raise InvalidInput(
            f"q has shape {motion.q.shape}; {arm.name} needs ({len(motion.t)}, {arm.n}) "
            f"for joints {arm.joint_names}"
        )
    if not (np.all(np.isfinite(motion.q)) and np.all(np.isfinite(motion.t))):
        raise InvalidInput("the run's times and joint positions must be finite")
    if len(motion.t) > 1 and np.any(np.diff(motion.t) <= 0):
        raise InvalidInput("the run's times must increase strictly")
    return motion, arm


def _check_rate(speed: float, fps: float) -> tuple[float, float]:
    speed, fps = float(speed), float(fps)
    if not (np.isfinite(speed) and speed > 0):
        raise InvalidInput(f"speed must be a finite number > 0, got {speed}")
    if not (np.isfinite(fps) and 0 < fps <= 240):
        raise InvalidInput(f"fps must be within (0, 240], got {fps}")
    return speed, fps


def _frame_times(t: np.ndarray, speed: float, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Replay times ``tau`` [s] every ``1/fps`` and the run times ``t0 + tau·speed`` they show."""
    span = float(t[-1] - t[0])
    length = span / speed
    count = max(1, int(math.ceil(length * fps - 1e-9)))
    tau = np.minimum(np.arange(count + 1) / fps, length)
    return tau, t[0] + tau * speed


def _interp_rows(t_new: np.ndarray, t: np.ndarray, values: np.ndarray) -> np.ndarray:
    if len(t) == 1:
        return np.repeat(values[:1], len(t_new), axis=0)
    return np.column_stack([np.interp(t_new, t, values[:, j]) for j in range(values.shape[1])])


# -- geometry helpers -----------------------------------------------------------------------


def _tube(
    points: np.ndarray, radius: float, sides: int = TUBE_SIDES
) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N·sides, 3) and faces of a tube of ``radius`` along a polyline.

    The rings follow the curve by parallel transport, so the tube does not twist.
    """
    keep = np.concatenate([[True], np.linalg.norm(np.diff(points, axis=0), axis=1) > 1e-9])
    p = points[keep]
    if len(p) < 2:
        p = np.vstack([points[:1], points[:1] + [radius * 1e-3, 0.0, 0.0]])
    tang = np.gradient(p, axis=0)
    tang /= np.maximum(np.linalg.norm(tang, axis=1, keepdims=True), 1e-12)
    seed = np.eye(3)[int(np.argmin(np.abs(tang[0])))]
    normal = seed - (seed @ tang[0]) * tang[0]
    normal /= np.linalg.norm(normal)
    theta = 2 * np.pi * np.arange(sides) / sides
    rings = []
    for k in range(len(p)):
        normal = normal - (normal @ tang[k]) * tang[k]
        normal /= max(np.linalg.norm(normal), 1e-12)
        binormal = np.cross(tang[k], normal)
        rings.append(
            p[k] + radius * (np.outer(np.cos(theta), normal) + np.outer(np.sin(theta), binormal))
        )
    vertices = np.vstack(rings)
    faces = []
    for k in range(len(p) - 1):
        for j in range(sides):
            a, b = k * sides + j, k * sides + (j + 1) % sides
            c, d = a + sides, b + sides
            faces += [(a, b, c), (b, d, c)]
    return vertices.astype(np.float32), np.asarray(faces, dtype=np.uint32)


def _decimate(points: np.ndarray, limit: int, must: Sequence[int] = ()) -> np.ndarray:
    """At most about ``limit`` rows of ``points``, evenly spaced, keeping the ends and ``must``."""
    n = len(points)
    if n <= limit:
        return points
    idx = set(np.linspace(0, n - 1, limit).round().astype(int).tolist()) | {
        i for i in must if 0 <= i < n
    }
    return points[sorted(idx)]


def _skeleton(arm: Arm, q: np.ndarray) -> pin.GeometryModel:
    """Balls at the joints, rods between them: a stand-in for arms without visual geometry."""
    import coal

    model, data = arm.model, arm.data
    pin.framesForwardKinematics(model, data, q)
    origins = [data.oMi[j].translation for j in range(1, model.njoints)] + [
        data.oMf[arm.frame_id].translation
    ]
    reach = max(1e-3, max(np.linalg.norm(a - b) for a in origins for b in origins))
    r = 0.025 * reach
    geom = pin.GeometryModel()
    for j in range(1, model.njoints):
        geom.addGeometryObject(
            pin.GeometryObject(
                f"joint_{model.names[j]}", j, pin.SE3.Identity(), coal.Sphere(1.3 * r)
            )
        )
        children = [c for c in range(j + 1, model.njoints) if model.parents[c] == j]
        ends = [model.jointPlacements[c].translation for c in children]
        if not children and model.frames[arm.frame_id].parentJoint == j:
            ends = [model.frames[arm.frame_id].placement.translation]
        for k, end in enumerate(ends):
            length = float(np.linalg.norm(end))
            if length < 1e-6:
                continue
            axis = end / length
            R = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), axis).toRotationMatrix()
            M = pin.SE3(R, end / 2)
            geom.addGeometryObject(
                pin.GeometryObject(f"link_{model.names[j]}_{k}", j, M, coal.Cylinder(r, length))
            )
    for g in geom.geometryObjects:
        g.meshColor = np.array([0.55, 0.57, 0.62, 1.0])
    return geom


def _display_model(arm: Arm, q0: np.ndarray, meshes: str) -> pin.GeometryModel:
    """A copy of the arm's visual model; ``meshes="compact"`` turns mesh files into triangles."""
    if arm.visual_model is None or len(arm.visual_model.geometryObjects) == 0:
        return _skeleton(arm, q0)
    geom = arm.visual_model.copy()
    if meshes == "compact":
        for g in geom.geometryObjects:
            if g.meshPath and type(g.geometry).__name__.startswith("BVHModel"):
                # Pinocchio then draws the triangles coal loaded (binary, about a quarter of the
                # size of the COLLADA text), coloured by meshColor, instead of the file itself.
                g.meshPath = ""
    return geom


def _lock_model(arm: Arm, geom: pin.GeometryModel, joint: str) -> pin.GeometryModel:
    """Copies, in :data:`LOCK_COLOR`, of the geometry moved directly by ``joint``."""
    jid = arm.model.getJointId(joint)
    locked = pin.GeometryModel()
    for g in geom.geometryObjects:
        if g.parentJoint != jid:
            continue
        c = g.copy()
        c.meshColor = np.array([*LOCK_COLOR, 1.0])
        c.overrideMaterial = True
        if type(c.geometry).__name__.startswith("BVHModel"):
            c.meshPath = ""  # triangles, so that the colour applies to a mesh file too
        locked.addGeometryObject(c)
    if len(locked.geometryObjects) == 0:  # nothing drawn on that link: a ball at the joint
        import coal

        extent = float(np.linalg.norm(arm.model.jointPlacements[jid].translation)) or 0.2
        ball = pin.GeometryObject(
            f"{joint}_locked", jid, pin.SE3.Identity(), coal.Sphere(0.25 * extent)
        )
        ball.meshColor = np.array([*LOCK_COLOR, 1.0])
        locked.addGeometryObject(ball)
    return locked


# -- recording the scene --------------------------------------------------------------------


class _Recorder:
    """Stands in for meshcat's ``ViewerWindow``: keeps the scene's commands instead of sending them.

    Commands are kept as meshcat's server keeps them (the last one per path and kind), in the
    order they were first sent, each as the three ZMQ frames meshcat uses: type, path, msgpack.
    """

    def __init__(self) -> None:
        self.commands: dict[tuple, tuple[bytes, bytes, bytes]] = {}
        self.meshes: set[str] = set()  # paths of objects the viewer draws as meshes

    def send(self, command) -> None:
        import umsgpack

        data = command.lower()
        key = (data["type"], data.get("path", ""), data.get("property"))
        if data["type"] == "set_object":
            kind = data["object"]["object"].get("type")
            (self.meshes.add if kind in ("Mesh", "_meshfile_object") else self.meshes.discard)(
                data["path"]
            )
        self.commands[key] = (
            data["type"].encode(),
            data.get("path", "").encode(),
            umsgpack.packb(data),
        )


class _Lowered:
    """A meshcat command given as its lowered dict (for commands meshcat has no class for)."""

    def __init__(self, data: dict) -> None:
        self.data = data

    def lower(self) -> dict:
        return self.data


def _f32(values: np.ndarray):
    """A float array as msgpack's Float32Array extension (meshcat's viewer decodes it)."""
    import umsgpack

    return umsgpack.Ext(0x17, np.ascontiguousarray(values, dtype=np.float32).tobytes())


def _quaternions(rotations: Sequence[np.ndarray]) -> np.ndarray:
    """three.js quaternions (x, y, z, w) of rotation matrices, sign-continuous for slerp."""
    out = np.array([pin.Quaternion(R).coeffs() for R in rotations])
    for k in range(1, len(out)):
        if out[k] @ out[k - 1] < 0:
            out[k] = -out[k]
    return out


def _rotation(xyzw: np.ndarray) -> np.ndarray:
    x, y, z, w = xyzw
    return pin.Quaternion(w, x, y, z).toRotationMatrix()


def _clip(path: str, tau: np.ndarray, positions=None, quaternions=None, visible=None) -> dict:
    """One animation entry for meshcat's ``set_animation``: a clip of tracks at ``path``."""
    tracks = []
    if positions is not None:
        tracks.append(
            {"name": ".position", "type": "vector3", "times": _f32(tau), "values": _f32(positions)}
        )
    if quaternions is not None:
        tracks.append(
            {
                "name": ".quaternion",
                "type": "quaternion",
                "times": _f32(tau),
                "values": _f32(quaternions),
            }
        )
    if visible is not None:
        times, values = visible
        if times[-1] <= times[0]:  # switched at time 0: one key
            times, values = times[-1:], values[-1:]
        tracks.append(
            {
                "name": ".visible",
                "type": "boolean",
                "times": [float(x) for x in times],
                "values": [bool(v) for v in values],
            }
        )
    # Times are in seconds: three.js scales them by 1/fps.
    return {"path": path, "clip": {"fps": 1.0, "name": "default", "tracks": tracks}}


@dataclass
class _Scene:
    """A recorded replay: meshcat commands (animation last) and what the page needs to know."""

    commands: list[tuple[bytes, bytes, bytes]]
    info: dict


def _tool_positions(arm: Arm, q: np.ndarray) -> np.ndarray:
    out = np.empty((len(q), 3))
    for k, qk in enumerate(q):
        pin.framesForwardKinematics(arm.model, arm.data, qk)
        out[k] = arm.data.oMf[arm.frame_id].translation
    return out


def _desired_positions(arm: Arm, x_des: np.ndarray | None, tool: np.ndarray) -> np.ndarray | None:
    """3-D points of the desired path: its linear rows, the others from the actual tool position."""
    lin = [i for i, r in enumerate(arm.task) if r in ("x", "y", "z")]
    if x_des is None or not lin:
        return None
    pts = tool.copy()
    for i in lin:
        pts[:, "xyz".index(arm.task[i])] = x_des[:, i]
    return pts


def _grid(points: np.ndarray):
    """A floor grid (z = 0) sized to the scene, with a round spacing: a scale for the eye.

    It replaces meshcat's 20 m grid, whose lines pass behind the camera of a close view (some
    software renderers then drop them).
    """
    import meshcat.geometry as mg

    span = float(max(np.ptp(points[:, 0]), np.ptp(points[:, 1]), 0.05))
    step = next(
        s for s in (0.01, 0.02, 0.05, 0.1, 0.2, 0.25, 0.5, 1.0, 2.0, 5.0, 1e9) if span / s <= 12
    )
    lo = np.floor((points[:, :2].min(0) - 0.4 * span) / step) * step
    hi = np.ceil((points[:, :2].max(0) + 0.4 * span) / step) * step
    segments = []
    for x in np.arange(lo[0], hi[0] + step / 2, step):
        segments += [(x, lo[1], 0.0), (x, hi[1], 0.0)]
    for y in np.arange(lo[1], hi[1] + step / 2, step):
        segments += [(lo[0], y, 0.0), (hi[0], y, 0.0)]
    geometry = mg.PointsGeometry(np.asarray(segments, dtype=np.float32).T)
    return mg.LineSegments(geometry, mg.LineBasicMaterial(color=0x9AA0AA))


def _camera(
    points: np.ndarray, radii: np.ndarray, path: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Scene centre and camera offset (world) that frame every point at the start.

    Planar scenes are seen from above at a slant; others from the front-right, turned towards
    the normal of the path's plane so that a circle shows as a circle rather than a line.
    """
    lo, hi = (points - radii[:, None]).min(0), (points + radii[:, None]).max(0)
    extent = np.ptp(points, axis=0)  # of the geometry origins and paths, not padded
    planar = extent[2] < 0.1 * max(extent[0], extent[1], 1e-9)
    az, el = (
        (np.radians(-90.0), np.radians(62.0)) if planar else (np.radians(-50.0), np.radians(24.0))
    )
    d = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    if not planar and path is not None and len(path) >= 3:
        centred = path - path.mean(0)
        _, s, vt = np.linalg.svd(centred, full_matrices=False)
        if s[0] > 1e-9 and s[-1] < 0.1 * s[0]:
            n = vt[-1] * (1.0 if vt[-1] @ d >= 0 else -1.0)
            d = d + 0.9 * n
            d /= np.linalg.norm(d)
    elev = np.degrees(np.arcsin(np.clip(d[2], -1, 1)))
    if elev < 12.0 or elev > 75.0:
        horiz = d[:2] / max(np.linalg.norm(d[:2]), 1e-9)
        e = np.radians(np.clip(elev, 12.0, 75.0))
        d = np.array([np.cos(e) * horiz[0], np.cos(e) * horiz[1], np.sin(e)])
    # camera axes: back (d), right, up
    up0 = np.array([0.0, 0.0, 1.0])
    right = np.cross(up0, d)
    right /= np.linalg.norm(right)
    up = np.cross(d, right)
    centre = (lo + hi) / 2
    rel = points - centre
    x, y, z = rel @ right, rel @ up, rel @ d
    shift = (
        right * (np.max(x + radii) + np.min(x - radii)) / 2
        + up * (np.max(y + radii) + np.min(y - radii)) / 2
    )
    centre = centre + shift
    rel = points - centre
    x, y, z = rel @ right, rel @ up, rel @ d
    tan_v = np.tan(np.radians(CAMERA_FOV / 2)) * 0.78  # margins for the legend and controls
    tan_h = tan_v * 1.3  # viewports are usually wider than high
    dist = max(
        np.max(z + (np.abs(y) + radii) / tan_v), np.max(z + (np.abs(x) + radii) / tan_h), 0.05
    )
    # lift the picture a little above the legend in the bottom-left corner
    centre = centre - up * 0.08 * dist * np.tan(np.radians(CAMERA_FOV / 2))
    return centre, d * dist


def _build_scene(
    run,
    arm: Arm | None,
    *,
    speed: float,
    fps: float,
    meshes: str = "compact",
    dt: float | None = None,
) -> _Scene:
    """Record the replay of ``run`` (motion, paths, lock colours, camera) as meshcat commands."""
    meshcat = _require_meshcat()
    import meshcat.geometry as mg
    from pinocchio.visualize import MeshcatVisualizer

    if meshes not in ("compact", "original"):
        raise InvalidInput(f"meshes must be 'compact' or 'original', got {meshes!r}")
    speed, fps = _check_rate(speed, fps)
    motion, arm = _load_motion(run, arm, dt)
    tau, t_frames = _frame_times(motion.t, speed, fps)
    q_frames = _interp_rows(t_frames, motion.t, motion.q)
    lock = motion.lock
    if lock is not None and lock.get("joint") not in arm.joint_names:
        raise InvalidInput(f"the locked joint {lock.get('joint')!r} is not among {arm.joint_names}")

    recorder = _Recorder()
    vis = meshcat.Visualizer(window=recorder)
    geom = _display_model(arm, motion.q[0], meshes)
    with _quiet():
        viz = MeshcatVisualizer(arm.model, None, geom)
        viz.initViewer(viewer=vis)
        viz.loadViewerModel(rootNodeName="robot")
        viz.display(motion.q[0])
    animations = []

    def placements(visualizer: MeshcatVisualizer):
        """Per geometry: positions (F, 3) and quaternions (F, 4) of its node over the frames."""
        gm, gd = visualizer.visual_model, visualizer.visual_data
        pos = np.empty((len(gm.geometryObjects), len(q_frames), 3))
        rot: list[list[np.ndarray]] = [[] for _ in gm.geometryObjects]
        for k, q in enumerate(q_frames):
            pin.forwardKinematics(arm.model, visualizer.data, q)
            pin.updateGeometryPlacements(arm.model, visualizer.data, gm, gd)
            for i in range(len(gm.geometryObjects)):
                M = gd.oMg[i]
                pos[i, k] = M.translation
                rot[i].append(M.rotation.copy())
        return pos, [_quaternions(r) for r in rot]

    pos, quats = placements(viz)
    # bounding spheres of the geometry over the frames, for the camera framing
    radii, centres = [], np.empty_like(pos)
    for i, g in enumerate(geom.geometryObjects):
        scale = np.asarray(g.meshScale, dtype=float)
        try:
            g.geometry.computeLocalAABB()
            radii.append(float(g.geometry.aabb_radius) * float(np.max(np.abs(scale))))
            local = np.asarray(g.geometry.aabb_center, dtype=float) * scale
        except Exception:  # pragma: no cover - geometry without a bounding box
            radii.append(0.0)
            local = np.zeros(3)
        centres[i] = pos[i] + np.array([_rotation(qk) @ local for qk in quats[i]])
    lock_tau = None
    locked_names: set[str] = set()
    if lock is not None:
        lock_tau = float(np.clip((lock["time"] - motion.t[0]) / speed, 0.0, tau[-1]))
        lgeom = _lock_model(arm, geom, lock["joint"])
        locked_names = {
            g.name
            for g in geom.geometryObjects
            if g.parentJoint == arm.model.getJointId(lock["joint"])
        }
        with _quiet():
            lviz = MeshcatVisualizer(arm.model, None, lgeom)
            lviz.initViewer(viewer=vis)
            lviz.loadViewerModel(rootNodeName="locked")
            lviz.display(motion.q[0])
        lpos, lquats = placements(lviz)
        for i, g in enumerate(lgeom.geometryObjects):
            node = lviz.getViewerNodeName(g, pin.GeometryType.VISUAL)
            vis[node].set_property("visible", lock_tau <= 0)
            animations.append(
                _clip(
                    vis[node].path.lower(),
                    tau,
                    lpos[i],
                    lquats[i],
                    visible=([0.0, lock_tau], [lock_tau <= 0, True]),
                )
            )
    for i, g in enumerate(geom.geometryObjects):
        node = vis[viz.getViewerNodeName(g, pin.GeometryType.VISUAL)].path.lower()
        shown = ([0.0, lock_tau], [lock_tau > 0, False]) if g.name in locked_names else None
        animations.append(_clip(node, tau, pos[i], quats[i], visible=shown))

    # paths: desired (dark), actual trace (teal), the moving target and the lock moment
    tool = _tool_positions(arm, motion.q)
    desired = _desired_positions(arm, motion.x_des, tool)
    scene_pts = [centres.reshape(-1, 3), tool]
    scene_r = [np.repeat(radii, len(q_frames)), np.zeros(len(tool))]
    if desired is not None:
        scene_pts.append(desired)
        scene_r.append(np.zeros(len(desired)))
    points, point_r = np.vstack(scene_pts), np.concatenate(scene_r)
    size = float(np.max(np.ptp(points, axis=0)))
    tube_r = max(0.0035 * size, 5e-4)
    k_lock = int(np.searchsorted(motion.t, lock["time"])) if lock else None
    must = [k_lock] if k_lock is not None else []
    extras = vis["replay"]
    if desired is not None:
        v, f = _tube(_decimate(desired, PATH_POINTS, must), tube_r)
        extras["desired_path"].set_object(
            mg.TriangularMeshGeometry(v, f), mg.MeshLambertMaterial(color=_hex(PATH_COLOR))
        )
        target = _interp_rows(t_frames, motion.t, desired)
        extras["target"].set_object(
            mg.Sphere(2.0 * tube_r), mg.MeshLambertMaterial(color=_hex(PATH_COLOR))
        )
        extras["target"].set_transform(_translation(target[0]))
        animations.append(_clip(extras["target"].path.lower(), tau, positions=target))
    v, f = _tube(_decimate(tool, PATH_POINTS, must), 0.6 * tube_r)
    extras["tool_trace"].set_object(
        mg.TriangularMeshGeometry(v, f), mg.MeshLambertMaterial(color=_hex(TRACE_COLOR))
    )
    if lock is not None:
        where = _interp_rows(
            np.array([lock["time"]]), motion.t, desired if desired is not None else tool
        )[0]
        extras["lock_moment"].set_object(
            mg.Sphere(3.2 * tube_r), mg.MeshLambertMaterial(color=_hex(LOCK_COLOR))
        )
        extras["lock_moment"].set_transform(_translation(where))

    # stage: light background, no axes helper, camera framing the whole arm and path
    vis["/Background"].set_property("top_color", list(BACKGROUND[0]))
    vis["/Background"].set_property("bottom_color", list(BACKGROUND[1]))
    vis["/Axes"].set_property("visible", False)
    vis["/Grid"].set_object(_grid(points))
    centre, offset = _camera(points, point_r, desired if desired is not None else tool)
    # meshcat's orbit controls look at the world origin, so the scene moves there, not the camera
    vis.set_transform(_translation(-centre))
    vis["/Grid"].set_transform(_translation(-centre))
    dx, dy, dz = offset
    vis["/Cameras/default/rotated/<object>"].set_property(
        "position", [float(dx), float(dz), float(-dy)]
    )

    vis.window.send(
        _Lowered(
            {
                "type": "set_animation",
                "path": "",
                "animations": animations,
                "options": {"play": True, "repetitions": 1},
            }
        )
    )
    commands = list(recorder.commands.values())
    commands.sort(key=lambda c: c[0] == b"set_animation")  # stable: the animation last
    meta = motion.meta
    info = {
        "robot": meta.get("robot", arm.name),
        "algorithm": meta.get("algorithm"),
        "joints": arm.joint_names,
        "speed": speed,
        "fps": fps,
        "run_start": float(motion.t[0]),
        "run_duration": float(motion.t[-1] - motion.t[0]),
        "duration": float(tau[-1]),
        "frames": len(tau),
        "lock": None
        if lock is None
        else {"joint": lock["joint"], "time": float(lock["time"]), "replay_time": lock_tau},
        "locked_geometry": sorted(locked_names),
        "meshes": len(recorder.meshes),
        "colors": {
            "lock": LOCK_COLOR,
            "trace": TRACE_COLOR,
            "path": PATH_COLOR,
            "links": {g.name: [float(c) for c in g.meshColor[:3]] for g in geom.geometryObjects},
        },
        "has_desired_path": desired is not None,
    }
    return _Scene(commands, info)


@contextlib.contextmanager
def _quiet():
    """Silence Pinocchio's visualizer notices (e.g. about get_image) while the scene is recorded."""
    import warnings

    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        yield


def _hex(rgb: Sequence[float]) -> int:
    r, g, b = (int(round(255 * float(c))) for c in rgb)
    return (r << 16) + (g << 8) + b


def _translation(p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T


# -- static HTML ----------------------------------------------------------------------------


def _viewer_js() -> str:
    meshcat = _require_meshcat()
    path = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
    text = path.read_text(encoding="utf-8")
    if "</script" in text.lower():  # pragma: no cover - would end the inline script early
        raise FaultToleranceError(f"{path} contains '</script'; it cannot be inlined")
    return text


_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="fault_tolerance {version} with meshcat">
<title>{title}</title>
<style>
  body {{ margin: 0; overflow: hidden;
          font-family: system-ui, -apple-system, "Segoe UI", sans-serif; }}
  #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
  #ft-legend {{ position: absolute; left: 12px; bottom: 12px; padding: 8px 12px; border-radius: 6px;
               background: rgba(255, 255, 255, 0.86); color: #1d1f24;
               font-size: 13px; line-height: 1.6;
               box-shadow: 0 1px 4px rgba(0, 0, 0, 0.18); pointer-events: none; }}
  #ft-legend b {{ font-weight: 600; }}
  .ft-swatch {{ display: inline-block; width: 22px; height: 5px; border-radius: 2px;
                vertical-align: middle; margin-right: 7px; }}
  .ft-dot {{ display: inline-block; width: 10px; height: 10px; border-radius: 5px;
             vertical-align: middle; margin: 0 13px 0 6px; }}
  #ft-clock {{ font-variant-numeric: tabular-nums; }}
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<div id="ft-legend">
  <div><b>{heading}</b></div>
  {legend}
  <div id="ft-clock">t = 0.00 s</div>
</div>
<script>
{viewer_js}
</script>
<script>
window.ftReplay = {info};
(function () {{
  var info = window.ftReplay;
  info.ready = false;
  info.errors = [];
  var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
  window.viewer = viewer;
  var commands = {commands};
  for (var i = 0; i < commands.length; i++) {{
    try {{
      var raw = atob(commands[i]);
      var bytes = new Uint8Array(raw.length);
      for (var j = 0; j < raw.length; j++) bytes[j] = raw.charCodeAt(j);
      viewer.handle_command_bytearray(bytes);
    }} catch (err) {{
      info.errors.push(String(err));
    }}
  }}
  // Show the animation controls (play, pause, time) and fold the long scene tree.
  try {{
    var folders = viewer.gui.__folders;
    if (folders["Scene"]) folders["Scene"].close();
    if (folders["Save / Load / Capture"]) folders["Save / Load / Capture"].close();
    viewer.gui.open();
  }} catch (err) {{
    info.errors.push(String(err));
  }}
  var clock = document.getElementById("ft-clock");
  function tick() {{
    var tau = viewer.animator ? viewer.animator.time : 0;
    var t = info.run_start + tau * info.speed;
    var text = "t = " + t.toFixed(2) + " s";
    if (info.speed !== 1) text += "  (replay \u00d7" + info.speed + ")";
    if (info.lock && t >= info.lock.time) text += "  \u2014 " + info.lock.joint + " locked";
    if (clock.textContent !== text) clock.textContent = text;
    requestAnimationFrame(tick);
  }}
  requestAnimationFrame(tick);
  info.ready = true;
}})();
</script>
</body>
</html>
"""


def _legend(info: dict) -> tuple[str, str, str]:
    """Title, heading and legend rows of the page."""
    esc = html_lib.escape
    robot = str(info.get("robot") or "arm")
    parts = [robot] + ([str(info["algorithm"]).upper()] if info.get("algorithm") else [])
    lock = info.get("lock")
    if lock:
        parts.append(f"{lock['joint']} locks at {lock['time']:.2f} s")
    heading = " \u00b7 ".join(parts)

    def css(rgb):
        return "rgb({},{},{})".format(*(int(round(255 * c)) for c in rgb))

    rows = []
    if info.get("has_desired_path"):
        rows.append(
            f'<div><span class="ft-swatch" style="background:{css(PATH_COLOR)}"></span>'
            f"desired path; the dark ball is where the tool should be</div>"
        )
    rows.append(
        f'<div><span class="ft-swatch" style="background:{css(TRACE_COLOR)}"></span>'
        f"the tool's actual trace</div>"
    )
    if lock:
        rows.append(
            f'<div><span class="ft-swatch" style="background:{css(LOCK_COLOR)}"></span>'
            f"{esc(lock['joint'])} locked from {lock['time']:.2f} s; the ball marks the lock</div>"
        )
    return f"fault_tolerance replay: {heading}", heading, "\n  ".join(rows)


def _static_html(scene: _Scene) -> str:
    from . import __version__

    title, heading, legend = _legend(scene.info)
    payload = [base64.b64encode(data).decode("ascii") for _, _, data in scene.commands]
    # "</" cannot occur in base64 or in this JSON of plain names and numbers, but escape anyway.
    info_json = json.dumps(scene.info).replace("</", "<\\/")
    return _PAGE.format(
        version=__version__,
        title=html_lib.escape(title),
        heading=html_lib.escape(heading),
        legend=legend,
        viewer_js=_viewer_js(),
        info=info_json,
        commands=json.dumps(payload, separators=(",", "\n")),
    )


def scene_commands(html: str) -> list[dict]:
    """The meshcat commands embedded in an exported replay page, decoded (for checks and tests)."""
    import umsgpack

    start = html.index("var commands = ") + len("var commands = ")
    end = html.index(";\n", start)
    return [umsgpack.unpackb(base64.b64decode(s)) for s in json.loads(html[start:end])]


def export_html(
    run,
    path: str | Path,
    arm: Arm | None = None,
    speed: float = 1.0,
    fps: float = 50.0,
    *,
    meshes: str = "compact",
    dt: float | None = None,
) -> Path:
    """Write the replay of ``run`` as one self-contained HTML file that plays offline.

    Args:
        run: A :class:`~fault_tolerance.simulation.Run`, a folder it was saved to, joint
            positions of shape (K, n) (with ``dt``) or a pair ``(t, q)``.
        path: The HTML file to write (atomically: a reader never sees half a file).
        arm: The arm (default: rebuilt from the run's metadata).
        speed: Replay speed factor (1: real time, 0.5: half speed).
        fps: Animation frames per replay second (the run's samples are interpolated).
        meshes: ``"compact"`` draws mesh files from the triangles Pinocchio loaded (binary,
            single colour, about a quarter of the size); ``"original"`` embeds the mesh files.
        dt: Time step [s] when ``run`` is an array of joint positions.

    Returns:
        The path written.

    Example:
        >>> export_html("out/run", "replay.html")  # doctest: +SKIP
    """
    scene = _build_scene(run, arm, speed=speed, fps=fps, meshes=meshes, dt=dt)
    return write_atomic(path, _static_html(scene))


def embed(run, arm: Arm | None = None, height: int = 400, *, speed: float = 1.0, fps: float = 25.0):
    """The replay for a Jupyter notebook: an iframe whose ``srcdoc`` is the self-contained page.

    The page lives in the notebook's output, so it survives saving the notebook and plays without
    a server. ``fps`` defaults to 25 to keep the notebook small (about 1.3 MB for a shipped arm).
    """
    scene = _build_scene(run, arm, speed=speed, fps=fps)
    page = _static_html(scene)
    srcdoc = page.replace("&", "&amp;").replace('"', "&quot;")
    markup = (
        f'<div style="height: {int(height)}px; width: 100%; overflow: hidden; resize: both">'
        f'<iframe srcdoc="{srcdoc}" style="width: 100%; height: 100%; border: none" '
        f'title="{html_lib.escape(_legend(scene.info)[0])}"></iframe></div>'
    )
    try:
        from IPython.display import HTML
    except ImportError:  # pragma: no cover - IPython comes with meshcat
        return _HTMLEmbed(markup)
    return HTML(markup)


class _HTMLEmbed:
    """Minimal rich-display object when IPython is not installed."""

    def __init__(self, markup: str) -> None:
        self.data = markup

    def _repr_html_(self) -> str:
        return self.data


# -- live server ----------------------------------------------------------------------------


def _serve_local(port: int | None = None) -> None:  # pragma: no cover - runs in the child process
    """Run meshcat's server with every socket on 127.0.0.1 (the body of the server process).

    meshcat's ``ZMQWebSocketBridge`` binds ZMQ to its ``host`` but starts its web server with
    ``app.listen(port)``, which listens on every interface; here ``listen`` gets the address.
    """
    import tornado.ioloop
    from meshcat.servers import zmqserver

    class LocalBridge(zmqserver.ZMQWebSocketBridge):
        def make_app(self):
            app = super().make_app()
            listen = app.listen

            def listen_local(port, address=None, **kwargs):
                return listen(port, address=LOCALHOST, **kwargs)

            app.listen = listen_local
            return app

    bridge = LocalBridge(host=LOCALHOST, port=port)
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    parent = os.getppid()

    def orphaned():
        if os.getppid() != parent:  # the replaying process died: do not linger
            bridge.ioloop.stop()

    tornado.ioloop.PeriodicCallback(orphaned, 1000).start()
    try:
        bridge.run()
    except KeyboardInterrupt:
        pass


class ReplayServer:
    """A meshcat server in a child process, bound to 127.0.0.1; ``close()`` stops it.

    Attributes:
        url: The viewer's URL (``http://127.0.0.1:PORT/static/``).
        zmq_url: Where scene commands are sent.
        process: The server process.
    """

    def __init__(self, process: subprocess.Popen, url: str, zmq_url: str, log: IO) -> None:
        self.process = process
        self.url = url
        self.zmq_url = zmq_url
        self._log = log
        self._socket = None
        self.info: dict = {}  # what was served (see export's window.ftReplay)
        atexit.register(self.close)

    @classmethod
    def start(cls, port: int | None = None, timeout: float = 30.0) -> ReplayServer:
        """Start the server process and wait until it says where it listens."""
        _require_meshcat()
        if port is not None and not (isinstance(port, int) and 0 < port < 65536):
            raise InvalidInput(f"port must be an integer in 1..65535, got {port!r}")
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[1])
        env["PYTHONPATH"] = os.pathsep.join(
            [root] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else [])
        )
        code = f"from fault_tolerance.viz import _serve_local; _serve_local({port!r})"
        log = tempfile.TemporaryFile()
        proc = subprocess.Popen(
            [sys.executable, "-u", "-c", code],
            stdout=subprocess.PIPE,
            stderr=log,
            stdin=subprocess.DEVNULL,
            env=env,
        )
        lines: queue.Queue = queue.Queue()

        def read():
            for raw in proc.stdout:
                lines.put(raw.decode("utf-8", "replace").strip())
            lines.put(None)

        threading.Thread(target=read, daemon=True).start()
        found: dict[str, str] = {}
        deadline = time.monotonic() + timeout
        while len(found) < 2:
            try:
                line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                line = None
            if line is None:
                proc.kill()
                proc.wait()
                log.seek(0)
                detail = log.read().decode("utf-8", "replace").strip().splitlines()[-1:] or [
                    "no output"
                ]
                log.close()
                where = f"port {port}" if port else "a free port"
                raise FaultToleranceError(
                    f"the meshcat server did not start on {where}: {detail[0]}"
                )
            key, _, value = line.partition("=")
            if key in ("zmq_url", "web_url"):
                found[key] = value
        return cls(proc, found["web_url"], found["zmq_url"], log)

    def send(self, commands: Sequence[tuple[bytes, bytes, bytes]], timeout: float = 30.0) -> None:
        """Send recorded scene commands (type, path, msgpack) to the server."""
        import zmq

        if self._socket is None:
            sock = zmq.Context.instance().socket(zmq.REQ)
            sock.setsockopt(zmq.LINGER, 0)
            sock.setsockopt(zmq.RCVTIMEO, int(timeout * 1000))
            sock.setsockopt(zmq.SNDTIMEO, int(timeout * 1000))
            sock.connect(self.zmq_url)
            self._socket = sock
        for frames in commands:
            self._socket.send_multipart(list(frames))
            reply = self._socket.recv()
            if reply != b"ok":
                raise FaultToleranceError(f"the meshcat server refused a command: {reply[:200]!r}")

    @property
    def running(self) -> bool:
        """Whether the server process is alive."""
        return self.process.poll() is None

    def close(self) -> None:
        """Stop the server (idempotent)."""
        if self._socket is not None:
            self._socket.close(linger=0)
            self._socket = None
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stdout is not None:
            self.process.stdout.close()
        if not self._log.closed:
            self._log.close()
        with contextlib.suppress(Exception):
            atexit.unregister(self.close)

    def __enter__(self) -> ReplayServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"ReplayServer({self.url!r}, {'running' if self.running else 'stopped'})"


def serve(
    run,
    arm: Arm | None = None,
    *,
    speed: float = 1.0,
    fps: float = 50.0,
    port: int | None = None,
    meshes: str = "compact",
    dt: float | None = None,
) -> tuple[str, ReplayServer]:
    """Serve the replay of ``run`` live: a meshcat server on 127.0.0.1, scene and animation loaded.

    Returns ``(url, server)``; open the URL in a browser (the animation plays when the page
    connects), call ``server.close()`` (or use it as a context manager) to stop the server.
    ``port`` is the web port (default: the first free one from 7000).
    """
    server = _serve_scene(_build_scene(run, arm, speed=speed, fps=fps, meshes=meshes, dt=dt), port)
    return server.url, server


def _serve_scene(scene: _Scene, port: int | None) -> ReplayServer:
    server = ReplayServer.start(port)
    try:
        server.send(scene.commands)
    except BaseException:
        server.close()
        raise
    server.info = scene.info
    return server


# -- entry points ---------------------------------------------------------------------------


class Replay(NamedTuple):
    """What :func:`replay` made: the HTML file written and/or the live URL and its server."""

    html: Path | None
    url: str | None
    server: ReplayServer | None


def replay(
    run,
    arm: Arm | None = None,
    *,
    speed: float = 1.0,
    fps: float = 50.0,
    open: bool = False,  # noqa: A002 - the CLI's flag
    html: str | Path | None = None,
    port: int | None = None,
    meshes: str = "compact",
    dt: float | None = None,
) -> Replay:
    """Replay ``run`` in the browser: a self-contained HTML file, a live viewer, or both.

    Args:
        run: A Run, the folder it was saved to, an array q (K, n) with ``dt``, or ``(t, q)``.
        arm: The arm (default: ``arm_from_meta(run.meta)``).
        speed: Replay speed factor (1: real time).
        fps: Animation frames per replay second.
        open: Start a live meshcat server on 127.0.0.1 (stop it with ``result.server.close()``).
        html: Write the replay to this HTML file.
        port: Web port of the live server (default: the first free one from 7000).
        meshes: ``"compact"`` or ``"original"`` (see :func:`export_html`).
        dt: Time step [s] when ``run`` is an array of joint positions.
    """
    if not open and html is None:
        raise InvalidInput("choose where to replay: open=True (live viewer) and/or html=FILE")
    if isinstance(run, (str, Path)):
        run = Run.load(run)
    if arm is None and isinstance(run, Run):
        arm = arm_from_meta(run.meta)
    scene = _build_scene(run, arm, speed=speed, fps=fps, meshes=meshes, dt=dt)
    path = write_atomic(html, _static_html(scene)) if html is not None else None
    server = _serve_scene(scene, port) if open else None
    return Replay(path, server.url if server else None, server)


def _wait_for_interrupt() -> None:  # pragma: no cover - blocks
    while True:
        time.sleep(3600)


def replay_main(
    run_dir: str | Path,
    open: bool = False,  # noqa: A002 - the CLI's flag
    html: str | None = None,
    speed: float = 1.0,
    *,
    fps: float = 50.0,
    port: int | None = None,
    wait: Callable[[], Any] | None = None,
    stdout: IO[str] | None = None,
    stderr: IO[str] | None = None,
) -> int:
    """``fault-tolerance replay RUN [--open | --html FILE] [--speed S]``; returns the exit code.

    With ``open`` it prints the URL and calls ``wait()`` (default: sleep until Ctrl-C), then
    stops the server. Exit codes: 0 done, 2 bad input (one line on stderr), 1 anything else.
    """
    out = stdout or sys.stdout
    err = stderr or sys.stderr
    if not open and not html:
        print("replay: choose --open (live viewer) or --html FILE (self-contained page)", file=err)
        return 2
    try:
        result = replay(run_dir, speed=speed, fps=fps, open=open, html=html, port=port)
    except FaultToleranceError as e:
        print(f"replay: {e}", file=err)
        return 2
    except ImportError as e:
        print(f"replay: {e}", file=err)
        return 1
    if result.html is not None:
        print(
            f"wrote {result.html} ({result.html.stat().st_size / 1e6:.1f} MB); "
            "open it in a browser",
            file=out,
        )
    if result.server is None:
        return 0
    print(
        f"meshcat replay at {result.url} (listening on 127.0.0.1 only); Ctrl-C stops it", file=out
    )
    out.flush()
    try:
        (wait or _wait_for_interrupt)()
    except KeyboardInterrupt:
        pass
    finally:
        result.server.close()
    return 0


__all__ = [
    "LOCALHOST",
    "Replay",
    "ReplayServer",
    "embed",
    "export_html",
    "replay",
    "replay_main",
    "scene_commands",
    "serve",
]
