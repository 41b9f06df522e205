"""Part plates as watertight triangle meshes: the hull of discs around the joints, minus pin holes.

manifold3d does the 2D hull, the holes and the extrusion, and guarantees a closed 2-manifold;
the binary STL is a few lines of numpy (trimesh, which the tests use to check the files, would
cost seconds of import time here). Plates are convex apart from their holes, which is also the
shape MuJoCo collides (the convex hull of a mesh): a turntable's disc too. A bent link
(`routing`) is not convex: it is written whole, to be made in one piece, and bar by bar, each
bar convex, for MuJoCo.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import NamedTuple

import numpy as np

SEGMENTS = 48  # polygon sides of a full circle
STL_RECORD = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])


class Solid(NamedTuple):
    """A closed triangle mesh: vertices (V, 3), triangles (F, 3), and its volume (as manifold3d
    measured it; the model needs it where MuJoCo's own is under its floor)."""

    vertices: np.ndarray
    faces: np.ndarray
    volume: float


def plate_mesh(
    points: np.ndarray,
    width: float,
    hole_diameter: float,
    thickness: float,
    holes: np.ndarray | None = None,
) -> Solid:
    """A plate through `points` (k, 2), z in [0, t], with pin holes at `holes` (all the points
    by default)."""
    import manifold3d

    outline = manifold3d.CrossSection.batch_hull(_discs(points, width / 2))
    return _solid(outline, points if holes is None else holes, hole_diameter, thickness)


def bent_mesh(chain: np.ndarray, width: float, hole_diameter: float, thickness: float) -> Solid:
    """A bent link through the points of `chain` (k, 2): one bar (the hull of two discs) per
    pair of neighbours, joined, with pin holes at the two ends; z in [0, t]."""
    import manifold3d

    discs = _discs(chain, width / 2)
    bars = [manifold3d.CrossSection.batch_hull(pair) for pair in itertools.pairwise(discs)]
    outline = manifold3d.CrossSection.batch_boolean(bars, manifold3d.OpType.Add)
    return _solid(outline, chain[[0, -1]], hole_diameter, thickness)


def strap_meshes(
    points: np.ndarray,
    bore: float,
    width: float,
    hole_diameter: float,
    thickness: float,
    hull: bool = True,
) -> tuple[Solid, list[Solid]]:
    """A strap (`strapped`): a ring of a half width round a bore of radius `bore` at points[0],
    a bar from the ring out to each other point, and the hull of those (two or more; not for
    a turntable's ring, whose posts stand all round the bore), with pin holes at those points.
    Returns the whole plate and its convex pieces for MuJoCo: the ring as quadrilaterals whose
    inner sides touch the bore, the bars and the hull."""
    import manifold3d

    centre, others = points[0], points[1:]
    outer = bore + width / 2
    pieces = _ring_pieces(centre, bore, outer, width)
    sides = len(pieces)
    ends = centre + outer * (others - centre) / np.linalg.norm(others - centre, axis=1)[:, None]
    pieces += [manifold3d.CrossSection.batch_hull(_discs(np.stack(pair), width / 2))
               for pair in zip(ends, others)]  # fmt: skip
    if hull and len(others) >= 2:
        pieces.append(manifold3d.CrossSection.batch_hull(_discs(others, width / 2)))
    disc = manifold3d.CrossSection.circle(outer, 4 * SEGMENTS).translate(tuple(centre))
    outline = manifold3d.CrossSection.batch_boolean([disc, *pieces[sides:]], manifold3d.OpType.Add)
    outline = outline - manifold3d.CrossSection.circle(bore, 4 * SEGMENTS).translate(tuple(centre))
    return _solid(outline, others, hole_diameter, thickness), [
        _solid(piece, others, hole_diameter, thickness) for piece in pieces
    ]


def ring_meshes(
    points: np.ndarray, hole: float, radius: float, hole_diameter: float, thickness: float
) -> tuple[Solid, list[Solid]]:
    """A turntable's ring (`turntable`): a disc of `radius` round points[0] with a hole of
    radius `hole`, and a pin hole at every other point. Returns the whole plate and its convex
    pieces for MuJoCo: quadrilaterals whose inner sides touch the hole and whose outer corners
    lie on the rim."""
    import manifold3d

    centre, others = points[0], points[1:]
    pieces = _ring_pieces(centre, hole, radius, radius - hole, inscribed=True)
    disc = manifold3d.CrossSection.circle(radius, 4 * SEGMENTS).translate(tuple(centre))
    outline = disc - manifold3d.CrossSection.circle(hole, 4 * SEGMENTS).translate(tuple(centre))
    solid = _solid(outline, others, hole_diameter, thickness)
    return solid, [_solid(piece, others, hole_diameter, thickness) for piece in pieces]


def _ring_pieces(
    centre: np.ndarray, inner: float, outer: float, width: float, inscribed: bool = False
) -> list:
    """A ring from radius `inner` to `outer` as convex quadrilaterals, the more the larger the
    ring is against `width`: their inner sides touch the inner circle, and their outer sides
    touch the outer one, or where `inscribed` their outer corners lie on it."""
    import manifold3d

    sides = int(np.clip(np.ceil(np.pi * np.sqrt(outer / (0.04 * width))), 16, 128))
    angles = np.arange(sides + 1) * (2 * np.pi / sides)
    unit = np.stack([np.cos(angles), np.sin(angles)], -1)
    rim = unit / np.cos(np.pi / sides)
    inside, rims = centre + inner * rim, centre + outer * (unit if inscribed else rim)
    quads = [[inside[k], rims[k], rims[k + 1], inside[k + 1]] for k in range(sides)]  # ccw
    return [manifold3d.CrossSection([np.array(quad).tolist()]) for quad in quads]


def disc_mesh(
    points: np.ndarray, radius: float, hole_diameter: float, thickness: float, centre_hole: bool
) -> Solid:
    """A disc of `radius` round points[0], with a pin hole at every other point, and at the
    centre too where a pin passes there (a sheave's; a turntable's disc has none)."""
    import manifold3d

    disc = manifold3d.CrossSection.circle(radius, 4 * SEGMENTS).translate(tuple(points[0]))
    return _solid(disc, points if centre_hole else points[1:], hole_diameter, thickness)


def _discs(points: np.ndarray, radius: float) -> list:
    import manifold3d

    circle = manifold3d.CrossSection.circle(radius, SEGMENTS)
    return [circle.translate((float(x), float(y))) for x, y in points]


def _solid(outline, holes: np.ndarray, hole_diameter: float, thickness: float) -> Solid:
    """The outline minus holes at `holes`, extruded to `thickness`."""
    import manifold3d

    for disc in _discs(holes, hole_diameter / 2):
        outline = outline - disc
    solid = outline.extrude(thickness)
    volume = float(solid.volume())
    if solid.status() != manifold3d.Error.NoError or not volume > 0:
        raise ValueError("the plate is not a closed solid (are its holes wider than the plate?)")
    mesh = solid.to_mesh()
    vertices = np.asarray(mesh.vert_properties[:, :3], dtype=np.float64)
    return Solid(vertices, np.asarray(mesh.tri_verts), volume)


def write_stl(path: Path, solid: Solid, name: str = "linkd") -> None:
    """Binary STL with outward unit normals (triangles counter-clockwise seen from outside)."""
    triangles = solid.vertices[solid.faces]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    records = np.zeros(len(solid.faces), dtype=STL_RECORD)
    records["normal"], records["vertices"] = normals, triangles
    header = name.encode("ascii", "replace")[:80].ljust(80, b" ")
    with open(path, "wb") as handle:
        handle.write(header + np.uint32(len(solid.faces)).tobytes())
        handle.write(records.tobytes())
