"""Every moving part holds the pins it turns on.

The physics checks follow joints and sites, not the parts' shapes: a model edited so that a
plate sits off its joints, or is scaled short of them, still moves exactly as mechanism.json
says. Here each pin point of a moving part (a hinge or loop-closure anchor) must lie inside the
outline of the part's own geoms (the plates on its body and the sheaves welded to it, not its
pins), at least a pin's radius in from its edge, where a hole round the pin leaves a wall (a
sheave centred there is no pin: an eccentric's centre needs no wall).
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from .pose import pin_points

CIRCLE = 32  # points of a cylinder's outline
SHEAVE = "_sheave"  # a sheave's name ends so: a disc a strap turns on, not a pin in a hole (an
# eccentric's centre, where a drive's rod turns, has no pin)
ROUNDING = 1e-9  # relative allowance, times the model's extent


def unheld_pins(model: Any, data: Any) -> list[str]:
    """A line for each pin point a moving part's own outline does not hold (at `data`'s pose)."""
    pins = pin_points(model, data)
    kinds = np.asarray(model.geom_type)
    cylinders = [g for g in np.flatnonzero(kinds == mujoco.mjtGeom.mjGEOM_CYLINDER)
                 if not _sheave(model, g)]  # fmt: skip
    weld = np.asarray(model.body_weldid)[model.geom_bodyid]
    centres = data.geom_xpos[cylinders, :2]
    extent = float(np.abs(data.geom_xpos[:, :2]).max(initial=1.0))
    problems = []
    for body, points in sorted(pins.items()):
        if body == 0:
            continue  # the ground: its pins stand in the base, the cover or brackets
        own = [g for g in np.flatnonzero(weld == body)
               if model.geom_bodyid[g] == body or _sheave(model, g)]  # fmt: skip
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body) or f"body {body}"
        if len(own) == 0:
            problems.append(f"part {name} has no geom of its own to hold its pins")
            continue
        outline = np.concatenate([_outline(model, data, g) for g in own])
        try:
            edges = ConvexHull(outline).equations  # rows n, d: n . x + d <= 0 inside
        except QhullError:
            problems.append(f"part {name} has no area")
            continue
        for point in points:
            depth = float(-(edges[:, :2] @ point + edges[:, 2]).max())
            near = np.linalg.norm(centres - point, axis=1) <= ROUNDING * extent + 1e-12
            need = min((model.geom_size[g, 0] for g, n in zip(cylinders, near) if n), default=0)
            if depth < need - ROUNDING * extent:
                x, y = point
                problems.append(f"part {name} does not hold its pin at ({x:.4g}, {y:.4g}) m: "
                                f"{max(depth, 0):.3g} m inside its outline, a pin's radius "
                                f"({need:.3g} m) needed")  # fmt: skip
    return problems


def _sheave(model: Any, geom: int) -> bool:
    """Whether a geom is a sheave (by its name): a disc a strap turns on, not a pin."""
    return (model.geom(geom).name or "").endswith(SHEAVE)


def _outline(model: Any, data: Any, geom: int) -> np.ndarray:
    """xy of points whose convex hull is the geom's outline seen along z (world frame)."""
    kind, size, types = model.geom_type[geom], model.geom_size[geom], mujoco.mjtGeom
    rotation, centre = data.geom_xmat[geom].reshape(3, 3), data.geom_xpos[geom]
    angles = np.arange(CIRCLE) * (2 * np.pi / CIRCLE)
    ring = np.stack([np.cos(angles), np.sin(angles), 0 * angles], 1)
    if kind == types.mjGEOM_MESH:
        mesh = model.geom_dataid[geom]
        start = model.mesh_vertadr[mesh]
        local = model.mesh_vert[start : start + model.mesh_vertnum[mesh]]
    elif kind == types.mjGEOM_BOX:
        local = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * size
    elif kind == types.mjGEOM_CYLINDER:  # its two end circles
        local = np.concatenate([size[0] * ring + [0, 0, h] for h in (-size[1], size[1])])
    else:  # a capsule's two end spheres, a sphere, or any other shape's bounding sphere
        ends = [[0, 0, -size[1]], [0, 0, size[1]]] if kind == types.mjGEOM_CAPSULE else [[0, 0, 0]]
        radius = (
            size[0]
            if kind in (types.mjGEOM_CAPSULE, types.mjGEOM_SPHERE)
            else model.geom_rbound[geom]
        )
        points = centre + np.array(ends) @ rotation.T
        return np.concatenate([point[:2] + radius * ring[:, :2] for point in points])
    return (centre + local @ rotation.T)[:, :2]
