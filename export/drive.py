"""The crank cut in two at the motor's shaft, its halves turned as one by a layshaft outside.

In a few mechanisms the parts passing over the motor's pivot must lie between the crank's arms:
no whole shaft there keeps clear of them (`braced.cut_crank_layers` finds these, last). The
motor's shaft is then cut into two stubs, as a ground pin's may be: the base stub carries the
crank's arms below the passing parts, the cover stub those above, each stub turning in its
plate. The two halves are two parts, each on a hinge of its own, and nothing inside the stack
joins them: a drive outside it does. A forked crank (`forked_rings`) may have arms of both
halves at one joint: there each arm's rod is its half's, and carries only its own part.

A layshaft stands beyond everything the mechanism sweeps, from under the base plate to over the
cover, turning in both. Under the base, two eccentric rods couple the base stub to it; over the
cover, two more couple the cover stub. Each rod is strapped at both ends round an eccentric
sheave (one on the stub, one on the layshaft, of equal throw and phase), so the rod keeps its
direction and the layshaft turns exactly as the stub does; the shafts pass through the
sheaves, which is why the rods are strapped rather than pinned. The two rods of a side are a
quarter turn apart: where one is in line with its two shafts (a dead point, where it would let
the layshaft turn either way) the other holds it. Each rod is made of two straps pinned
together at its middle; the sheaves are keyed on their shafts, and the layshaft is its shaft
and its four sheaves.

The drive's points (the layshaft's axis, the sheaves' centres, the rods' middles) are joints
appended after the mechanism's own (`Drive.points`): in the assembly pose, each turning with
the crank about its centre (`Drive.centres`), so their paths follow from the crank angle alone.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from linkd.mechanism import Mechanism

from .layers import Arm, Layout, Shaft, Strap, sweep
from .options import Sizes
from .parts import Assembly, Hinge, Loop, Part, Pin

MARGIN = 2.0  # link widths between the layshaft and the farthest point the mechanism sweeps
THROW = 4.0  # link widths from a shaft to its sheaves' centres


@dataclass(frozen=True)
class Drive:
    """The drive of a crank cut in two: parts `upper` (the cover stub's half) and `layshaft`;
    its points are joints `first`, `first + 1`, ..."""

    upper: int
    layshaft: int
    first: int
    points: tuple[tuple[float, float], ...]  # assembly pose, mechanism units
    centres: tuple[tuple[float, float], ...]  # each point turns with the crank about its centre
    pin: int  # the motor's pin, cut into stubs
    layers: tuple[int, int]  # the lowest and highest layer of the drive
    turns: tuple[tuple[str, float], ...]  # each of its hinges, and its angle per crank angle

    def hinge_angles(self, angles: np.ndarray) -> dict[str, np.ndarray]:
        """The drive's hinges at the crank angles: the upper half and the layshaft turn with the
        crank, each rod keeps its direction (so turns back on its half)."""
        return {name: rate * np.asarray(angles, dtype=np.float64) for name, rate in self.turns}

    def describe(self) -> dict:
        """mechanism.json's `drive`: the points, and the centres they turn about."""
        return {"first_joint": self.first, "points": [list(p) for p in self.points],
                "centres": [list(c) for c in self.centres]}  # fmt: skip


def _halves(
    assembly: Assembly, layout: Layout
) -> tuple[list[Arm], list[Arm], set[tuple[int, int | None]]] | None:
    """The crank's arms on the base stub and on the cover stub, where the motor's shaft is cut
    and no arm joins the two halves elsewhere, and what the upper half holds: (joint, None) for
    a joint only it reaches, (joint, part) for a part turning on its rod at a joint both reach
    (a forked crank's arms carry one rod each there, `forked`). None where one rigid crank is
    left."""
    crank, pivot = assembly.crank.child, assembly.crank.joint
    k = next(k for k, pin in enumerate(assembly.pins) if pin.joint == pivot)
    arms = layout.arms.get(crank, ())
    if k not in layout.cover_stubs or not arms:
        return None
    group = {j: j for arm in arms for j in arm.joints if j != pivot}

    def root(j: int) -> int:
        while group[j] != j:
            j = group[j]
        return j

    for arm in arms:
        ends = [j for j in arm.joints if j != pivot]
        if len(ends) == 2:
            group[root(ends[0])] = root(ends[1])
    high = layout.cover_stubs[k][0]
    upper = {root(j) for arm in arms if pivot in arm.joints and arm.layer >= high
             for j in arm.joints if j != pivot}  # fmt: skip
    lower = {root(j) for arm in arms if pivot in arm.joints and arm.layer < high
             for j in arm.joints if j != pivot}  # fmt: skip
    if not upper or not lower:
        return None
    above: set[tuple[int, int | None]] = {(j, None) for j in group if root(j) in upper - lower}
    for j in upper & lower:  # both halves reach it: only where each rod there is one half's
        fork = next((f for n, f in layout.forks.items() if assembly.pins[n].joint == j), None)
        if fork is None or fork.part != crank or any(root(i) == j != i for i in group):
            return None
        for parts, (lo, hi) in fork.rods:
            sides = {arm.layer >= high for arm in arms
                     if j in arm.joints and lo <= arm.layer <= hi}  # fmt: skip
            if len(sides) != 1:
                return None
            if sides == {True}:
                above |= {(j, p) for p in parts}
    on_top = [arm.layer >= high if pivot in arm.joints else root(arm.joints[0]) in upper
              for arm in arms]  # fmt: skip
    return ([a for a, top in zip(arms, on_top) if not top],
            [a for a, top in zip(arms, on_top) if top], above)  # fmt: skip


def cut_cleanly(assembly: Assembly, layout: Layout) -> bool:
    """Whether the crank is whole at the motor, or cut there into two halves a drive can turn
    (a search that may cut it can find a cut no drive can turn: `_halves`)."""
    crank, pivot = assembly.crank.child, assembly.crank.joint
    k = next(k for k, pin in enumerate(assembly.pins) if pin.joint == pivot)
    if k not in layout.cover_stubs:
        return True
    sides = {arm.layer >= layout.cover_stubs[k][0] for arm in layout.arms.get(crank, ())
             if pivot in arm.joints}  # fmt: skip
    return len(sides) < 2 or _halves(assembly, layout) is not None


def drive(
    mech: Mechanism, assembly: Assembly, layout: Layout, sizes: Sizes
) -> tuple[Mechanism, Assembly, Layout]:
    """The mechanism with the drive's points appended (for its parts' shapes only), and the
    assembly and layout with the crank cut in two and the drive's parts added; all unchanged
    where the crank is one rigid part (`_halves`)."""
    halves = _halves(assembly, layout)
    if halves is None:
        return mech, assembly, layout
    lower, upper, above = halves
    crank, pivot = assembly.crank.child, assembly.crank.joint
    motor = next(k for k, pin in enumerate(assembly.pins) if pin.joint == pivot)
    discs = [(strap.joint, strap.radius) for strap in layout.straps]
    points, centres = _points(mech, pivot, sweep(mech, sizes.link_width), sizes.link_width, discs)
    cut, half, owner = _cut(assembly, above, motor)
    n, top = len(mech.positions), layout.count - 1
    axis, rod_layers = n, (-1, -2, top + 1, top + 2)  # joint n: the layshaft's axis
    rod_joints = [(n + 1 + 3 * r, n + 2 + 3 * r, n + 3 + 3 * r) for r in range(4)]  # A, B, M
    parts, first = list(cut.parts), len(cut.parts)
    layshaft, rods = first, list(range(first + 1, first + 5))
    parts.append(Part("drive_layshaft", "plate", (axis, *(b for _, b, _ in rod_joints))))
    parts += [Part(f"drive_rod{r}", "plate", joints) for r, joints in enumerate(rod_joints)]
    shaft_pin = len(cut.pins)
    pins = [*cut.pins, Pin("drive_layshaft_shaft", axis, layshaft, (0, layshaft))]
    on = [crank, crank, half, half]  # the half each rod's stub sheave is fixed on
    hinges = [*cut.hinges, Hinge("hinge_drive_layshaft", layshaft, 0, axis)]
    hinges += [Hinge(f"hinge_drive_rod{r}", rod, on[r], rod_joints[r][0])
               for r, rod in enumerate(rods)]  # fmt: skip
    loops = [*cut.loops, *(Loop(f"loop_drive_rod{r}", rod, layshaft, rod_joints[r][1])
                           for r, rod in enumerate(rods))]  # fmt: skip
    arms = {p: a for p, a in layout.arms.items() if p != crank}
    arms |= {crank: tuple(lower), half: tuple(upper), layshaft: ()}  # the layshaft: no plate
    radius = THROW * sizes.link_width + sizes.link_width / 2 + sizes.clearance
    straps, shafts = [], []
    for r, (rod, layer, (a, b, m)) in enumerate(zip(rods, rod_layers, rod_joints)):
        arms[rod] = (Arm((a, m), layer), Arm((b, m), layer))
        straps += [Strap(rod, a, on[r], radius, (motor,), (a, m)),
                   Strap(rod, b, layshaft, radius, (shaft_pin,), (b, m))]  # fmt: skip
        shafts.append(Shaft(rod, m, (layer, layer)))
    kept = [replace(s, part=owner(s.part, s.joint),  # a sheave keyed on its strap's rod
                    sheave_of=owner(s.sheave_of, s.joint, s.part))
            for s in layout.straps]  # fmt: skip
    kept_shafts = [replace(s, part=owner(s.part, s.joint)) for s in layout.shafts]
    forks = {}
    for k, fork in layout.forks.items():  # each rod fixed in the half whose arm holds it
        hubs = tuple(owner(fork.part, cut.pins[k].joint, parts[0]) for parts, _ in fork.rods)
        forks[k] = replace(fork, part=hubs[0], hubs=hubs if len(set(hubs)) > 1 else ())
    low, high = min(rod_layers), max(rod_layers)
    levels = [*layout.layers, min(a.layer for a in upper), low, *rod_layers]
    spans = [*layout.pin_spans, (low, high)]
    spans[motor] = (low, spans[motor][1])  # the stubs run on to the drive's sheaves
    stubs = {**layout.cover_stubs, motor: (layout.cover_stubs[motor][0], high)}
    turns = ((f"hinge_{parts[half].name}", 1.0), ("hinge_drive_layshaft", 1.0),
             *((f"hinge_drive_rod{r}", -1.0) for r in range(4)))  # fmt: skip
    info = Drive(half, layshaft, n, tuple(map(tuple, points)), tuple(map(tuple, centres)),
                 motor, (low, high), turns)  # fmt: skip
    ground = np.concatenate([mech.fixed, [True], np.zeros(len(points) - 1, bool)])
    shapes = mech.replace(positions=np.concatenate([mech.positions, points]), fixed=ground)
    driven = replace(layout, layers=np.array(levels), pin_spans=spans, cover_stubs=stubs,
                     arms=arms, straps=(*kept, *straps), shafts=(*kept_shafts, *shafts),
                     forks=forks, drive=info)  # fmt: skip
    return shapes, Assembly(parts, hinges, pins, loops), driven


def _points(
    mech: Mechanism,
    pivot: int,
    paths: np.ndarray,
    width: float,
    discs: Sequence[tuple[int, float]] = (),
) -> tuple[np.ndarray, np.ndarray]:
    """The drive's points in the assembly pose, and the centres they turn about: the layshaft's
    axis (MARGIN link widths beyond the mechanism's reach from the pivot, the sheaves `discs`,
    (joint, radius), included, towards its farthest ground joint, so the frame grows least),
    then for each rod the centre of its sheave on the stub, of its sheave on the layshaft and
    its middle; the two rods of a side a quarter turn apart, each an eighth of a turn from its
    dead points."""
    centre = mech.positions[pivot]
    fixed = mech.positions[mech.fixed] - centre
    far = fixed[np.argmax(np.linalg.norm(fixed, axis=1))]
    toward = far / np.linalg.norm(far) if np.linalg.norm(far) > 0 else np.array([1.0, 0.0])
    reach = float(np.linalg.norm(paths - centre, axis=-1).max())
    for joint, radius in discs:
        reach = max(reach, float(np.linalg.norm(paths[joint] - centre, axis=-1).max()) + radius)
    axis = centre + (reach + MARGIN * width) * toward
    phases = np.arctan2(toward[1], toward[0]) + np.pi / 4 + np.array([0, np.pi / 2] * 2)
    points, centres = [axis], [axis]
    for phase in phases:
        throw = THROW * width * np.array([np.cos(phase), np.sin(phase)])
        points += [centre + throw, axis + throw, (centre + axis) / 2 + throw]
        centres += [centre, axis, (centre + axis) / 2]
    return np.array(points), np.array(centres)


def _cut(
    assembly: Assembly, above: set[tuple[int, int | None]], motor: int
) -> tuple[Assembly, int, Callable[..., int]]:
    """The assembly with the crank's upper half (`above`, as `_halves` gives it) a new part,
    hinged at the motor's pivot right after the crank (parents before children), which carries
    what the crank carried there. Returns it, the half's index, and which part now holds what
    part p held at joint j (for part `other`, where both halves reach j)."""
    crank, pivot = assembly.crank.child, assembly.crank.joint
    part, half = assembly.parts[crank], len(assembly.parts)
    only = {j for j, other in above if other is None}
    both = {j for j, other in above if other is not None}
    mine = sorted({pivot, *only, *both})
    lower = tuple(j for j in part.joints if j not in only)
    links = tuple(e for e in part.links if set(e) <= set(mine))
    parts = [*assembly.parts, Part(f"{part.name}_upper", part.kind, tuple(mine), links)]
    parts[crank] = replace(part, joints=lower)

    def owner(p: int, j: int, other: int | None = None) -> int:
        return half if p == crank and (j in only or (j, other) in above) else p

    hinges = []
    for h in assembly.hinges:
        hinges.append(replace(h, parent=owner(h.parent, h.joint, h.child)))
        if h is assembly.crank:
            hinges.append(Hinge(f"hinge_{parts[half].name}", half, 0, pivot))
    pins = [replace(pin, hub=owner(pin.hub, pin.joint),
                    members=tuple(owner(m, pin.joint) for m in pin.members)
                    + ((half,) if k == motor or pin.joint in both else ()))
            for k, pin in enumerate(assembly.pins)]  # fmt: skip
    loops = [replace(loop, part=owner(loop.part, loop.joint, loop.hub),
                     hub=owner(loop.hub, loop.joint, loop.part))
             for loop in assembly.loops]  # fmt: skip
    return Assembly(parts, hinges, pins, loops), half, owner
