"""Recording a replay as meshcat commands: the robot, its animation, the paths and the camera.

:func:`_build_scene` draws the arm with Pinocchio's ``MeshcatVisualizer`` into a
:class:`_Recorder` that keeps meshcat's commands instead of sending them, and returns them as a
:class:`_Scene`; the static page (:mod:`.page`) inlines them, the live server (:mod:`.server`)
sends them. meshcat is imported here, lazily, by :func:`_require_meshcat`.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.viz.geometry import (
    BACKGROUND,
    LOCK_COLOR,
    PATH_COLOR,
    PATH_POINTS,
    TRACE_COLOR,
    _camera,
    _decimate,
    _desired_positions,
    _display_model,
    _grid,
    _hex,
    _lock_model,
    _quaternions,
    _rotation,
    _tool_positions,
    _translation,
    _tube,
)
from fault_tolerance.viz.motion import (
    _check_rate,
    _frame_times,
    _interp_rows,
    _load_motion,
    _Motion,
)


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
    motion: _Motion  # what was replayed (for the page's plots)
    arm: Arm


def _build_scene(
    run,
    arm: Arm | None,
    *,
    speed: float,
    fps: float,
    meshes: str = "compact",
    dt: float | None = None,
    package_dirs=(),
) -> _Scene:
    """Record the replay of ``run`` (motion, paths, lock colours, camera) as meshcat commands.

    ``package_dirs``: where ``package://`` meshes of a run's carried arm may be read.
    """
    meshcat = _require_meshcat()
    from pinocchio.visualize import MeshcatVisualizer

    if meshes not in ("compact", "original"):
        raise InvalidInput(f"meshes must be 'compact' or 'original', got {meshes!r}")
    speed, fps = _check_rate(speed, fps)
    motion, arm = _load_motion(run, arm, dt, package_dirs)
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
    pos, quats = _placements(arm, viz, q_frames)
    radii, centres = _bounding_spheres(geom, pos, quats)
    animations: list[dict] = []
    lock_tau, locked_names = None, set()
    if lock is not None:
        lock_tau = float(np.clip((lock["time"] - motion.t[0]) / speed, 0.0, tau[-1]))
        locked_names, clips = _lock_ghost(
            vis, arm, geom, motion.q[0], q_frames, tau, lock, lock_tau
        )
        animations += clips
    for i, g in enumerate(geom.geometryObjects):
        node = vis[viz.getViewerNodeName(g, pin.GeometryType.VISUAL)].path.lower()
        ghost = g.name in locked_names  # names only when a joint locks, at lock_tau
        shown = ([0.0, lock_tau], [lock_tau > 0, False]) if ghost and lock_tau is not None else None
        animations.append(_clip(node, tau, pos[i], quats[i], visible=shown))
    paths = _draw_paths(vis, arm, motion, t_frames, tau, centres, radii, len(q_frames))
    animations += paths.clips
    _stage(vis, paths.points, paths.point_r, paths.focus)
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
    info = _scene_info(motion, arm, speed, fps, tau, lock_tau, locked_names, recorder, geom)
    info["has_desired_path"] = paths.desired is not None
    return _Scene(commands, info, motion, arm)


def _placements(arm: Arm, visualizer, q_frames: np.ndarray):
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


def _bounding_spheres(geom, pos: np.ndarray, quats: list) -> tuple[list[float], np.ndarray]:
    """Radii and centres (per geometry and frame) of the geometry's bounding spheres (camera)."""
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
    return radii, centres


def _lock_ghost(vis, arm: Arm, geom, q0, q_frames, tau, lock: dict, lock_tau: float):
    """The lock colours: a copy of the locked links, shown from the lock moment on.

    Returns the names of the geometry the locked joint moves and the clips of its coloured copy.
    """
    from pinocchio.visualize import MeshcatVisualizer

    lgeom = _lock_model(arm, geom, lock["joint"])
    joint = arm.model.getJointId(lock["joint"])
    locked = {g.name for g in geom.geometryObjects if g.parentJoint == joint}
    clips = []
    with _quiet():
        lviz = MeshcatVisualizer(arm.model, None, lgeom)
        lviz.initViewer(viewer=vis)
        lviz.loadViewerModel(rootNodeName="locked")
        lviz.display(q0)
    lpos, lquats = _placements(arm, lviz, q_frames)
    for i, g in enumerate(lgeom.geometryObjects):
        node = lviz.getViewerNodeName(g, pin.GeometryType.VISUAL)
        vis[node].set_property("visible", lock_tau <= 0)
        clips.append(
            _clip(
                vis[node].path.lower(),
                tau,
                lpos[i],
                lquats[i],
                visible=([0.0, lock_tau], [lock_tau <= 0, True]),
            )
        )
    return locked, clips


@dataclass
class _Paths:
    """What :func:`_draw_paths` drew: the points framed by the camera, its clips, the focus."""

    points: np.ndarray
    point_r: np.ndarray
    desired: np.ndarray | None
    focus: np.ndarray
    clips: list[dict]


def _draw_paths(vis, arm: Arm, motion, t_frames, tau, centres, radii, frames: int) -> _Paths:
    """Paths: desired (dark), actual trace (teal), the moving target and the lock moment."""
    import meshcat.geometry as mg

    lock = motion.lock
    tool = _tool_positions(arm, motion.q)
    desired = _desired_positions(arm, motion.x_des, tool)
    scene_pts = [centres.reshape(-1, 3), tool]
    scene_r = [np.repeat(radii, frames), np.zeros(len(tool))]
    if desired is not None:
        scene_pts.append(desired)
        scene_r.append(np.zeros(len(desired)))
    points, point_r = np.vstack(scene_pts), np.concatenate(scene_r)
    size = float(np.max(np.ptp(points, axis=0)))
    tube_r = max(0.0035 * size, 5e-4)
    k_lock = int(np.searchsorted(motion.t, lock["time"])) if lock else None
    must = [k_lock] if k_lock is not None else []
    extras, clips = vis["replay"], []
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
        clips.append(_clip(extras["target"].path.lower(), tau, positions=target))
    v, f = _tube(_decimate(tool, PATH_POINTS, must), 0.6 * tube_r)
    extras["tool_trace"].set_object(
        mg.TriangularMeshGeometry(v, f), mg.MeshLambertMaterial(color=_hex(TRACE_COLOR))
    )
    focus = desired if desired is not None else tool
    if lock is not None:
        where = _interp_rows(np.array([lock["time"]]), motion.t, focus)[0]
        extras["lock_moment"].set_object(
            mg.Sphere(3.2 * tube_r), mg.MeshLambertMaterial(color=_hex(LOCK_COLOR))
        )
        extras["lock_moment"].set_transform(_translation(where))
    return _Paths(points, point_r, desired, focus, clips)


def _stage(vis, points: np.ndarray, point_r: np.ndarray, focus: np.ndarray) -> None:
    """Light background, no axes helper, camera framing the whole arm and path."""
    vis["/Background"].set_property("top_color", list(BACKGROUND[0]))
    vis["/Background"].set_property("bottom_color", list(BACKGROUND[1]))
    vis["/Axes"].set_property("visible", False)
    vis["/Grid"].set_object(_grid(points))
    centre, offset = _camera(points, point_r, focus)
    # meshcat's orbit controls look at the world origin, so the scene moves there, not the camera
    vis.set_transform(_translation(-centre))
    vis["/Grid"].set_transform(_translation(-centre))
    dx, dy, dz = offset
    vis["/Cameras/default/rotated/<object>"].set_property(
        "position", [float(dx), float(dz), float(-dy)]
    )


def _scene_info(motion, arm: Arm, speed, fps, tau, lock_tau, locked_names, recorder, geom) -> dict:
    """What the page needs to know about the replay (robot, timing, lock, colours)."""
    meta, lock = motion.meta, motion.lock
    return {
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
    }


@contextlib.contextmanager
def _quiet():
    """Silence Pinocchio's visualizer notices (e.g. about get_image) while the scene is recorded."""
    import warnings

    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        yield
