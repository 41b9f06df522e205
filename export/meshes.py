"""Part plates as watertight triangle meshes: the hull of discs around the joints, minus pin holes.

manifold3d does the 2D hull, the holes and the extrusion, and guarantees a closed 2-manifold;
the binary STL is a few lines of numpy (trimesh, which the tests use to check the files, would
cost seconds of import time here). Plates are convex apart from their holes, which is also the
shape MuJoCo collides (the convex hull of a mesh).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

SEGMENTS = 48  # polygon sides of a full circle
STL_RECORD = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])


def plate_mesh(
    points: np.ndarray, width: float, hole_diameter: float, thickness: float
) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and triangles (F, 3) of a plate through `points` (k, 2), z in [0, t]."""
    import manifold3d

    def discs(radius: float) -> list:
        circle = manifold3d.CrossSection.circle(radius, SEGMENTS)
        return [circle.translate((float(x), float(y))) for x, y in points]

    outline = manifold3d.CrossSection.batch_hull(discs(width / 2))
    holes = manifold3d.CrossSection.batch_boolean(discs(hole_diameter / 2), manifold3d.OpType.Add)
    solid = (outline - holes).extrude(thickness)
    if solid.status() != manifold3d.Error.NoError or not solid.volume() > 0:
        raise ValueError("the plate is not a closed solid (are its holes wider than the plate?)")
    mesh = solid.to_mesh()
    return np.asarray(mesh.vert_properties[:, :3], dtype=np.float64), np.asarray(mesh.tri_verts)


def write_stl(path: Path, vertices: np.ndarray, faces: np.ndarray, name: str = "linkd") -> None:
    """Binary STL with outward unit normals (triangles counter-clockwise seen from outside)."""
    triangles = vertices[faces]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    records = np.zeros(len(faces), dtype=STL_RECORD)
    records["normal"], records["vertices"] = normals, triangles
    header = name.encode("ascii", "replace")[:80].ljust(80, b" ")
    with open(path, "wb") as handle:
        handle.write(header + np.uint32(len(faces)).tobytes())
        handle.write(records.tobytes())


def write_plate(
    path: Path, points: np.ndarray, width: float, hole: float, thickness: float
) -> None:
    """Write a plate (sizes in metres) as a binary STL."""
    write_stl(path, *plate_mesh(points, width, hole, thickness), name=f"linkd {path.stem}")
