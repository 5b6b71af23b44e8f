"""What the replay draws and from where: colours, tubes, stand-in links, lock copies, grid, camera.

Pure geometry on NumPy and Pinocchio (meshcat only for the grid's line object, imported lazily):
the tubes that draw the paths, a skeleton for arms without visual geometry, the magenta copies of
the locked joint's link, the floor grid and a camera that frames the whole scene.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from fault_tolerance.model.arm import Arm

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
    reach = max(1e-3, max(float(np.linalg.norm(a - b)) for a in origins for b in origins))
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


def _hex(rgb: Sequence[float]) -> int:
    r, g, b = (int(round(255 * float(c))) for c in rgb)
    return (r << 16) + (g << 8) + b


def _translation(p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T
