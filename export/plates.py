"""The solid plates of a layered assembly: what is cut, meshed and modelled, part by part.

The ground is a base plate under the stack, maybe a cover over it (both holding a layshaft
where the crank is driven from one, `drive`), brackets inside it, frames between modules and
turntables' rings; each moving part is one plate (a disc or a ring on a
turntable), or one per arm where it is split, and a strap's part has a sheave besides.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from linkd.mechanism import Mechanism

from .layers import Layout, Strap
from .parts import Assembly
from .rods import pin_rods


@dataclass(frozen=True)
class Plate:
    """A solid plate of a part on one layer (the ground has a base and maybe a cover)."""

    name: str
    part: int
    joints: tuple[int, ...]  # joints it has holes for
    layer: int
    bends: tuple[tuple[float, float], ...] = ()  # waypoints of a bent link, between its joints
    posts: tuple[tuple[float, float], ...] = ()  # ground posts it holds (outline and holes)
    bore: float = 0.0  # a strap's or ring's: the radius of its bore round its first joint
    sheave: float = 0.0  # a sheave: a disc of this radius round its first joint
    disc: float = 0.0  # a turntable's: a disc of this radius round its first joint (a ring: bored)


def plates(assembly: Assembly, layout: Layout) -> list[Plate]:
    """Every plate of the layout: the ground's base (and cover), brackets and frames, the
    sheaves of straps, then one per moving part, or one per arm of a split part. Where there
    are frames, base, frames and cover hold the frames' posts too."""
    ground = assembly.parts[0]
    held = {b.joint for b in layout.brackets}
    base = tuple(j for j in ground.joints if j not in layout.top_joints and j not in held)
    stubs = (assembly.pins[k].joint for k in layout.cover_stubs)
    cover = tuple(sorted({*layout.top_joints, *stubs}))
    tables = layout.turntables
    rings = posts(layout)[len(layout.brackets) :]  # the rings' posts, then the frames'
    low = tuple(b.post for b in layout.brackets if not b.top) + layout.frame_posts
    low += tuple(point for point, (lo, _) in rings if lo == 0 and point not in low)
    high = tuple(b.post for b in layout.brackets if b.top) + layout.frame_posts
    high += tuple(p for p, (_, hi) in rings if hi == layout.count - 1 and p not in high)
    if layout.frames:  # each ground plate holds the rods that end in it or pass it
        ends = [(rod.joint, rod.span) for rod in pin_rods(assembly, layout) if 0 in rod.members]
        base, cover = _held(ends, 0), _held(ends, layout.count - 1)
    if layout.drive:  # the layshaft turns in both
        shaft = (layout.drive.first,)
        base, cover = base + shaft, cover + shaft
    out = [Plate(ground.name, 0, base, 0, posts=low)] if base or low else []
    if cover or high:
        out.append(Plate(f"{ground.name}_cover", 0, cover, layout.count - 1, posts=high))
    for k, b in enumerate(layout.brackets):
        out.append(Plate(f"{ground.name}_bracket{k}", 0, (b.joint,), b.layer, posts=(b.post,)))
    for k, layer in enumerate(layout.frames):
        out.append(Plate(f"{ground.name}_frame{k}", 0, _held(ends, layer), layer,
                         posts=layout.frame_posts))  # fmt: skip
    for k, table in enumerate(tables):  # a ring round each, with a bar out to each post
        out.append(Plate(f"{ground.name}_ring{k or ''}", 0, (table.joint,), table.layer,
                         posts=tuple(dict.fromkeys(table.posts)), bore=table.bore))  # fmt: skip
    straps = {(strap.part, strap.arm): strap for strap in layout.straps}
    for strap in layout.straps:
        through = (assembly.pins[k].joint for k in strap.passing)
        layer = int(layout.layers[strap.part])
        if strap.arm:  # an arm's strap: on that arm's layer
            layer = layout.arms[strap.part][_strap_arm(layout, strap)].layer
        out.append(Plate(sheave_name(assembly, layout, strap), strap.sheave_of,
                         (strap.joint, *through), layer, sheave=strap.radius))  # fmt: skip
    for p, part in enumerate(assembly.parts[1:], start=1):
        if (p, ()) in straps:
            strap = straps[p, ()]
            joints = (strap.joint, *(j for j in part.joints if j != strap.joint))
            out.append(Plate(part.name, p, joints, int(layout.layers[p]), bore=strap.radius))
            continue
        table = next((table for table in tables if table.part == p), None)
        if table:
            joints = (table.joint, *(j for j in part.joints if j != table.joint))
            out.append(Plate(part.name, p, joints, table.layer, bore=table.hole,
                             disc=table.radius))  # fmt: skip
            continue
        for k, arm in enumerate(layout.arms.get(p, ())):
            strap = straps.get((p, arm.joints))  # an arm turning on a sheave: bored round it
            if strap is None:
                out.append(Plate(f"{part.name}_arm{k}", p, arm.joints, arm.layer))
                continue
            joints = (strap.joint, *(j for j in arm.joints if j != strap.joint))
            out.append(Plate(f"{part.name}_arm{k}", p, joints, arm.layer, bore=strap.radius))
        if p not in layout.arms:
            bends = tuple(map(tuple, layout.bends.get(p, np.empty((0, 2))).tolist()))
            out.append(Plate(part.name, p, part.joints, int(layout.layers[p]), bends))
    return out


def _held(ends: list[tuple[int, tuple[int, int]]], layer: int) -> tuple[int, ...]:
    """The joints of the ground's rods (joint, span) that reach a ground plate on `layer`."""
    return tuple(sorted({joint for joint, (lo, hi) in ends if lo <= layer <= hi}))


def sheave_name(assembly: Assembly, layout: Layout, strap: Strap) -> str:
    """The sheave's plate and body: named after the strap that turns on it (its part, or its
    arm's plate)."""
    name = assembly.parts[strap.part].name
    return f"{name}_arm{_strap_arm(layout, strap)}_sheave" if strap.arm else f"{name}_sheave"


def _strap_arm(layout: Layout, strap: Strap) -> int:
    """The index among its part's arms of the arm a strap is (where `strap.arm` is set)."""
    return [arm.joints for arm in layout.arms.get(strap.part, ())].index(strap.arm)


def plate_points(mech: Mechanism, plate: Plate) -> np.ndarray:
    """(k, 2) points a plate is made round, each with a hole: its joints, then its posts."""
    return np.concatenate([mech.positions[list(plate.joints)], np.reshape(plate.posts, (-1, 2))])


def posts(layout: Layout) -> list[tuple[tuple[float, float], tuple[int, int]]]:
    """Each ground post's axis and (lowest, highest) layer: a bracket's from the base or down
    from the cover, the turntables' rings' from the base to the highest ring (or the spans a
    ground ring's lug posts are given, each once), then the frames' from the base to the
    cover."""
    top = layout.count - 1
    out = [(b.post, (b.layer, top) if b.top else (0, b.layer)) for b in layout.brackets]
    shared = [table for table in layout.turntables if not table.spans]
    top_ring = max((table.layer for table in shared), default=0)
    out += [(point, (0, top_ring)) for point in (shared[0].posts if shared else ())]
    lugged = (zip(table.posts, table.spans) for table in layout.turntables if table.spans)
    out += list(dict.fromkeys(post for posts in lugged for post in posts))
    return out + [(point, (0, top)) for point in layout.frame_posts]
