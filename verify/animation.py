"""`animation.html`: a standalone meshcat page playing one crank revolution in a loop.

meshcat's viewer is a single JavaScript bundle shipped in its wheel. The page inlines that bundle
and the viewer commands (set_object, set_transform, set_animation, msgpack-encoded, as meshcat's
own `static_html` does), so it opens offline from a file and needs no server to be written. The
parts move with the analytic kinematics of mechanism.json; the traced path and the target curve
are drawn as lines (the target at the resolution a screen shows, however many points it has).
The scene is centred and scaled so the mechanism spans about two viewer units.
"""

from __future__ import annotations

import base64
import html
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from linkd.mechanism import UNITS_IN_METRES, Mechanism
from linkd.outdir import write_atomic

from .analytic import all_positions, joint_paths, rigid_parts
from .screen import screen_polyline

FRAMES = 120  # animation keyframes per revolution
PERIOD = 4.0  # seconds per revolution
ROOT = "/meshcat/linkd"
COLOURS = (0x4E79A7, 0xF28E2B, 0x59A14F, 0xB07AA1, 0xEDC948, 0x76B7B2, 0xFF9DA7, 0x9C755F)
GROUND_COLOUR = 0x808080
CAMERA = ("Cameras", "default", "rotated", "<object>")


@dataclass
class Part:
    """A rigid part to draw: the joints it carries and its surface in the assembly pose.

    joints: mechanism joint indices (two of them fix its motion; all fixed means it stays put).
    vertices: (V, 3) in mechanism units, assembly pose; faces: (F, 3) vertex indices.
    """

    name: str
    joints: tuple[int, ...]
    vertices: np.ndarray
    faces: np.ndarray
    colour: int | None = None  # 0xRRGGBB; default from a palette


def prism(outline: np.ndarray, z0: float, z1: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a convex counter-clockwise (K, 2) outline extruded from z0 to z1."""
    k = len(outline)
    bottom = np.column_stack([outline, np.full(k, z0)])
    top = np.column_stack([outline, np.full(k, z1)])
    ring = np.arange(k)
    following = (ring + 1) % k
    fan = ring[1:-1]
    faces = np.concatenate(
        [
            np.column_stack([np.zeros(k - 2, int), fan + 1, fan]),  # bottom, facing -z
            np.column_stack([np.full(k - 2, k), fan + k, fan + 1 + k]),  # top, facing +z
            np.column_stack([ring, following, following + k]),
            np.column_stack([ring, following + k, ring + k]),
        ]
    )
    return np.vstack([bottom, top]), faces


def rounded_outline(points: np.ndarray, radius: float, segments: int = 24) -> np.ndarray:
    """Counter-clockwise convex hull of circles of `radius` around (P, 2) points."""
    from scipy.spatial import ConvexHull

    theta = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    circle = radius * np.column_stack([np.cos(theta), np.sin(theta)])
    cloud = (points[:, None, :] + circle[None]).reshape(-1, 2)
    return cloud[ConvexHull(cloud).vertices]  # scipy orders 2-D hulls counter-clockwise


def default_parts(mech: Mechanism) -> list[Part]:
    """Each rigid part as a rounded plate on its own layer (width and thickness from the scale)."""
    width = 0.08 * mech.scale
    parts = []
    for layer, joints in enumerate(rigid_parts(mech)):
        if not joints:
            continue
        outline = rounded_outline(mech.positions[list(joints)], width / 2)
        z0 = (layer - 1) * 1.5 * width / 2
        vertices, faces = prism(outline, z0, z0 + width / 2)
        name = "ground" if layer == 0 else f"part{layer}"
        parts.append(Part(name, joints, vertices, faces))
    return parts


def parts_from_model(xml_path: str | Path, mech: Mechanism) -> list[Part]:
    """The exported model's geoms (STL plates, pins), one part per rigid body, assembly pose.

    A body's joints are the mechanism joints at its pins (hinge and loop-closure anchors);
    mesh, box and cylinder geoms are drawn, in the model's colours.
    """
    import mujoco

    from .pose import pin_points

    model = mujoco.MjModel.from_xml_path(str(xml_path))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    unit = UNITS_IN_METRES[mech.units]
    weld = model.body_weldid[model.geom_bodyid]
    pins = pin_points(model, data)
    positions = all_positions(mech)
    fixed = tuple(int(k) for k in np.flatnonzero(mech.fixed))
    parts = []
    for body in np.unique(weld):
        geoms = np.flatnonzero(weld == body)
        anchors = pins.get(int(body), np.zeros((0, 2))) / unit
        nearest = np.linalg.norm(anchors[:, None] - positions, axis=-1).argmin(1)
        joints = fixed if body == 0 else tuple(dict.fromkeys(int(k) for k in nearest))
        shapes = [s for s in (_geom_surface(model, data, g) for g in geoms) if s is not None]
        if not shapes or (body and len(joints) < 2):
            continue
        vertices = np.vstack([v for v, _ in shapes]) / unit
        offsets = np.cumsum([0] + [len(v) for v, _ in shapes[:-1]])
        faces = np.vstack([f + o for (_, f), o in zip(shapes, offsets)])
        colour = int.from_bytes(bytes(int(255 * c) for c in model.geom_rgba[geoms[0], :3]), "big")
        first = int(model.geom_bodyid[geoms[0]])
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, first) or f"body{first}"
        parts.append(Part(name, joints, vertices, faces, colour))
    return parts


def _geom_surface(model: object, data: object, geom: int) -> tuple | None:
    """World vertices (metres) and faces of a mesh, box or cylinder geom; None for others."""
    import mujoco

    kind, size = model.geom_type[geom], model.geom_size[geom]
    if kind == mujoco.mjtGeom.mjGEOM_MESH:
        mesh = model.geom_dataid[geom]
        v0, nv = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
        f0, nf = model.mesh_faceadr[mesh], model.mesh_facenum[mesh]
        local, faces = model.mesh_vert[v0 : v0 + nv], model.mesh_face[f0 : f0 + nf]
    elif kind == mujoco.mjtGeom.mjGEOM_BOX:
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * size[:2]
        local, faces = prism(corners, -size[2], size[2])
    elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        theta = np.linspace(0, 2 * np.pi, 24, endpoint=False)
        circle = size[0] * np.column_stack([np.cos(theta), np.sin(theta)])
        local, faces = prism(circle, -size[1], size[1])
    else:
        return None
    world = data.geom_xpos[geom] + local @ data.geom_xmat[geom].reshape(3, 3).T
    return world, np.asarray(faces, dtype=np.int64)


def part_displacements(part: Part, paths: np.ndarray) -> np.ndarray:
    """(T, 4, 4) rigid transforms taking the part from its assembly pose to each frame."""
    t = paths.shape[1]
    poses = np.tile(np.eye(4), (t, 1, 1))
    moving = [j for j in part.joints if np.ptp(paths[j], axis=0).max() > 0]
    if not moving:
        return poses
    a, b = (part.joints[0], part.joints[1]) if len(part.joints) > 1 else (moving[0], moving[0])
    d0 = paths[b, 0] - paths[a, 0]
    d = paths[b] - paths[a]
    turn = np.arctan2(d[:, 1], d[:, 0]) - np.arctan2(d0[1], d0[0]) if a != b else np.zeros(t)
    c, s = np.cos(turn), np.sin(turn)
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = c, -s, s, c
    rotated = np.stack(
        [c * paths[a, 0, 0] - s * paths[a, 0, 1], s * paths[a, 0, 0] + c * paths[a, 0, 1]], -1
    )
    poses[:, :2, 3] = paths[a] - rotated
    return poses


def _quaternions(poses: np.ndarray) -> np.ndarray:
    """(T, 4) x, y, z, w quaternions (three.js order) of rotations about z."""
    half = 0.5 * np.arctan2(poses[:, 1, 0], poses[:, 0, 0])
    quat = np.zeros((len(poses), 4))
    quat[:, 2], quat[:, 3] = np.sin(half), np.cos(half)
    # Keep consecutive keys in one hemisphere so interpolation takes the short way round.
    flip = np.cumsum(np.r_[0, (quat[1:] * quat[:-1]).sum(1) < 0]) % 2 == 1
    quat[flip] *= -1
    return quat


def _root_transform(points: np.ndarray) -> np.ndarray:
    """Centre the drawing at the origin and scale it to about two viewer units across."""
    low, high = points.min(0), points.max(0)
    size = max(float(np.max(high - low)), 1e-12)
    matrix = np.eye(4)
    matrix[:3, :3] *= 2.0 / size
    matrix[:2, 3] = -(low + high)[:2] / 2 * 2.0 / size
    return matrix


def import_meshcat() -> Any:
    """meshcat, imported without the deprecation warning its server module raises on import."""
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"meshcat\.")
        import meshcat
    return meshcat


def scene_commands(
    mech: Mechanism, target: np.ndarray | None = None, parts: Sequence[Part] | None = None
) -> list[dict[str, Any]]:
    """meshcat viewer commands (lowered dicts) drawing and animating the mechanism."""
    import_meshcat()
    from meshcat import geometry as g
    from meshcat.animation import Animation, AnimationClip
    from meshcat.commands import SetAnimation, SetObject, SetProperty, SetTransform
    from meshcat.path import Path as MeshcatPath

    parts = default_parts(mech) if parts is None else list(parts)
    paths = joint_paths(mech, FRAMES)
    paths = np.concatenate([paths, paths[:, :1]], 1)  # the last frame closes the loop
    root = MeshcatPath(tuple(ROOT.strip("/").split("/")))
    drawn = [paths.reshape(-1, 2)] + ([np.asarray(target)[:, :2]] if target is not None else [])
    commands = [
        SetTransform(_root_transform(np.vstack(drawn)), root),
        SetProperty("visible", False, MeshcatPath(("Axes",))),
        # Look down on the plane from the front (the camera node's frame has y up, z = -y world).
        SetProperty("position", [0.0, 2.0, 0.9], MeshcatPath(CAMERA)),
    ]
    animation = Animation(default_framerate=FRAMES / PERIOD)
    for k, part in enumerate(parts):
        colour = part.colour
        if colour is None:
            still = all(mech.fixed[list(part.joints)])
            colour = GROUND_COLOUR if still else COLOURS[k % len(COLOURS)]
        path = root.append("parts").append(part.name)
        geometry = g.TriangularMeshGeometry(part.vertices, part.faces)
        commands.append(SetObject(geometry, g.MeshLambertMaterial(color=colour), path))
        poses = part_displacements(part, paths)
        quats = _quaternions(poses)
        clip = animation.clips[path] = AnimationClip(fps=animation.default_framerate)
        for frame in range(len(poses)):
            clip.set_property(frame, "position", "vector3", poses[frame, :3, 3].tolist())
            clip.set_property(frame, "quaternion", "quaternion", quats[frame].tolist())
    lift = max(float(part.vertices[:, 2].max()) for part in parts) if parts else 0.0
    ee = paths[mech.end_effector]
    commands.append(_line(ee[:-1], lift, 0xD62728, root.append("traced_path")))
    stroke = mech.crank_range is not None  # an open path: draw it open, and the working stroke
    if target is not None:
        drawn_target = screen_polyline(np.asarray(target)[:, :2])
        target_line = _line(drawn_target, lift, 0x1F77B4, root.append("target"), closed=not stroke)
        commands.append(target_line)
    if stroke:
        working = joint_paths(mech, np.linspace(*mech.crank_range, FRAMES))[mech.end_effector]
        commands.append(_line(working, lift, 0x2CA02C, root.append("working_stroke"), False))
    commands.append(SetAnimation(animation, play=True, repetitions=float("inf")))
    return _stable_ids([command.lower() for command in commands])


def _stable_ids(lowered: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The commands with meshcat's time-based object ids replaced by numbered ones (references
    between objects kept), so the same mechanism always gives the same page."""
    ids: dict[str, str] = {}

    def collect(node: Any) -> None:
        if isinstance(node, dict):
            if isinstance(node.get("uuid"), str):
                ids.setdefault(node["uuid"], str(uuid.UUID(int=len(ids) + 1)))
            for value in node.values():
                collect(value)
        elif isinstance(node, list):
            for value in node:
                collect(value)

    def renamed(node: Any) -> Any:
        if isinstance(node, dict):
            return {key: renamed(value) for key, value in node.items()}
        if isinstance(node, list):
            return [renamed(value) for value in node]
        return ids.get(node, node) if isinstance(node, str) else node

    collect(lowered)
    return renamed(lowered)


def _line(points: np.ndarray, z: float, colour: int, path: Any, closed: bool = True) -> Any:
    """A polyline command, closed unless asked otherwise."""
    from meshcat import geometry as g
    from meshcat.commands import SetObject

    xyz = np.column_stack([points, np.full(len(points), z)]).astype(np.float32)
    kind = g.LineLoop if closed else g.Line
    line = kind(g.PointsGeometry(xyz.T), g.LineBasicMaterial(color=colour, linewidth=2))
    return SetObject(line, path=path)


def page(commands: list[dict[str, Any]], title: str) -> str:
    """The standalone HTML page replaying `commands` in meshcat's bundled viewer."""
    import umsgpack

    meshcat = import_meshcat()
    bundle = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
    blobs = ",\n".join(
        '"' + base64.b64encode(umsgpack.packb(command)).decode("ascii") + '"'
        for command in commands
    )
    return f"""<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>
body {{ margin: 0; }}
#meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<script>
{bundle.read_text(encoding="utf-8")}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
[{blobs}].forEach(function (blob) {{
  var bytes = Uint8Array.from(atob(blob), function (c) {{ return c.charCodeAt(0); }});
  viewer.handle_command_bytearray(bytes);
}});
</script>
</body>
</html>
"""


def model_parts(xml_path: Path, mech: Mechanism) -> list[Part] | None:
    """The parts of an exported model if there is one that loads, else None."""
    if not xml_path.is_file():
        return None
    from .checks import capture_warnings

    with capture_warnings():
        try:
            return parts_from_model(xml_path, mech)
        except ValueError:
            return None


def write_animation(
    mech: Mechanism,
    path: str | Path,
    target: np.ndarray | None = None,
    parts: Sequence[Part] | None = None,
) -> None:
    """Write the standalone playback page of `mech` (with the `target` curve, if given) to `path`.

    parts: the shapes to draw; by default the plates and pins of the `mechanism.xml` beside
    `path` when there is one (write it first), else rounded plates on separate layers.
    Raises ValueError when the mechanism does not turn through a revolution.
    """
    path = Path(path)
    if parts is None:
        parts = model_parts(path.parent / "mechanism.xml", mech)
    title = f"linkd: {mech.n_nodes}-joint mechanism"
    write_atomic(path, page(scene_commands(mech, target, parts), title))
