"""Eccentric straps: a part made as a strap round a sheave, so that pins may pass through it.

In some mechanisms a pin's path, seen from a part that turns about a joint of another part,
runs over that joint: a coupler hung on the crank tip sweeps over the crank's pivot, whose
shaft must then stay off the coupler's layer, and no order of the stack allows it. A steam
engine's valve gear meets the same problem with an eccentric: the crank is a disc (the
sheave) wider than its throw, fixed on the shaft, and the rod ends in a ring (the strap) that
turns round the disc. The shaft passes through the disc, inside the strap, and never meets it.

Here a strap is part A at a joint J it shares with part B: A's plate has a bore round J, and
a sheave, a disc fixed in B on A's layer, fills it. The sheave's radius reaches past every
one of B's other joints whose pin comes near A (each keeps the hole radius and the clearance
inside it), and A must keep its other joints clear of the bore. Those pins may then cross A's
layer through the sheave; in exchange A's outline grows by the sheave's disc, which other
parts and pins must keep clear of like any plate. No strap turns at the motor pivot: the
motor's shaft is there. One strap is tried, then two, the ones freeing the most pin crossings
first; and last of all the constructions, sets of more round a core of straps
(`several_straps_layers`). None is searched unless freeing every candidate crossing with no
disc added (looser than any choice) layers at all.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterator
from dataclasses import replace
from itertools import chain, combinations, islice

import numpy as np

from .layers import (
    Conflicts,
    Layout,
    NoFlatLayers,
    Strap,
    find_conflicts,
    largest_step,
    outlines,
    stack_layers,
)
from .options import Sizes
from .parts import Assembly
from .planar import convex_hull, cross, least_distances, point_segment, to_segment

MAX_STRAPS = 120  # layer searches per width before the construction gives up


def strapped_layers(
    assembly: Assembly, paths: np.ndarray, sizes: Sizes, searches: int | None = None
) -> Layout:
    """Layers with one or two parts made straps (NoFlatLayers when no choice tried layers),
    within MAX_STRAPS layer searches or `searches` if fewer."""
    conflicts = find_conflicts(assembly, paths, sizes)
    return strap_search(assembly, conflicts, paths, sizes, searches)


def several_straps_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with more straps at once, round a core of them (`_around_core`), where one or two
    do not do: tried after every other construction, so what those build is left as it is."""
    conflicts = find_conflicts(assembly, paths, sizes)
    return strap_search(assembly, conflicts, paths, sizes, core=True)


def strap_search(
    assembly: Assembly,
    conflicts: Conflicts,
    paths: np.ndarray,
    sizes: Sizes,
    searches: int | None = None,
    then: Callable[[Conflicts], Conflicts] = lambda conflicts: conflicts,
    whole: Collection[int] = (),
    core: bool = False,
    shafts: Collection[int] = (),
) -> Layout:
    """The straps' search on given conflicts, each choice's conflicts passed through `then`
    before it is layered (another construction's rules on top: `turntable`), no part of
    `whole` made a strap: the first MAX_STRAPS choices (or `searches` if fewer) of one strap
    or two, or with `core` of the sets round a core of straps instead. The pins `shafts` (a
    split part's, `braced`) stay whole at the ground."""
    budget = min(MAX_STRAPS, searches or MAX_STRAPS)
    options = [s for s in _candidates(assembly, conflicts, paths[:, 0], sizes)
               if s.part not in whole]  # fmt: skip
    freed = {s: _inside(assembly, paths[:, 0], sizes, s) & _near(conflicts, s) for s in options}

    def loose(chosen: list[Strap]) -> bool:  # their crossings freed, with no disc: looser
        blocked = [[q for q in near if not any(k in freed[s] and q == s.part for s in chosen)]
                   for k, near in enumerate(conflicts.blocked)]  # fmt: skip
        layered = _layered(assembly, then(replace(conflicts, blocked=blocked)), sizes, shafts)
        return layered is not None

    if not budget or not options or not loose(options):
        raise NoFlatLayers("no strap frees the pins that keep the stack from layering")
    ranked = sorted(options, key=lambda s: -len(freed[s]))  # stable: the candidates' order
    few = chain(((s,) for s in ranked), combinations(ranked, 2))  # one strap, then two
    choices = _around_core(ranked, loose) if core else few
    swept = _Swept(assembly, paths, sorted({s.joint for s in options}))
    for chosen in islice(choices, budget):
        if len({s.part for s in chosen}) < len(chosen):
            continue
        strapped = _with_straps(assembly, conflicts, swept, sizes, chosen)
        layout = _layered(assembly, then(strapped), sizes, shafts)
        if layout is not None:
            straps = tuple(_passing(assembly, paths[:, 0], sizes, layout, s) for s in chosen)
            return replace(layout, straps=straps)
    raise NoFlatLayers("no strap tried lets the stack layer")


def _around_core(ranked: list[Strap], loose: Callable[[list[Strap]], bool]) -> Iterator[tuple]:
    """Where one or two straps do not do, more may: a core of straps, the fewest whose crossings
    freed (with no disc) still layer, found by leaving out each in turn, the least freeing
    first; then the core with one strap swapped for another, each only where it too layers
    with no disc. Their discs may still clash, which the real search then finds."""
    core = list(ranked)
    for strap in reversed(ranked):
        fewer = [s for s in core if s is not strap]
        if loose(fewer):
            core = fewer
    yield tuple(core)
    for k in range(len(core)):
        for other in (s for s in ranked if s not in core):
            swapped = [*core[:k], other, *core[k + 1 :]]
            if len({s.part for s in swapped}) == len(swapped) and loose(swapped):
                yield tuple(swapped)


def _candidates(
    assembly: Assembly, conflicts: Conflicts, positions: np.ndarray, sizes: Sizes
) -> list[Strap]:
    """Every strap that frees a pin crossing: part A near pin P, at a joint J of a part B that
    also has P's joint; the sheave reaches P with the hole radius and clearance to spare, and
    A's other joints stay a width clear of the bore. None turns at the motor pivot: the motor's
    shaft there is the crank's, and a sheave on it would be carried by nothing else."""
    margin = sizes.hole_diameter / 2 + sizes.clearance
    radius: dict[tuple[int, int, int], float] = {}
    for k, pin in enumerate(assembly.pins):
        for a in conflicts.blocked[k]:
            for b, part in enumerate(assembly.parts):
                if b == a or pin.joint not in part.joints:
                    continue
                for j in set(assembly.parts[a].joints) & set(part.joints) - {pin.joint}:
                    r = float(np.linalg.norm(positions[pin.joint] - positions[j])) + margin
                    radius[a, j, b] = max(radius.get((a, j, b), 0.0), r)
    motor = assembly.crank.joint
    out = []
    for (a, j, b), r in sorted(radius.items()):
        others = positions[[k for k in assembly.parts[a].joints if k != j]]
        clear = _distance_to_hull(positions[j], others) - sizes.link_width / 2 - margin
        if j == motor or clear < r:
            continue
        out.append(Strap(a, j, b, r, ()))
    return out


def _distance_to_hull(point: np.ndarray, points: np.ndarray) -> float:
    """From a point to the convex hull of `points` (0 inside it)."""
    z, zs = point[0] + 1j * point[1], points[:, 0] + 1j * points[:, 1]
    hull = zs[convex_hull(points)]
    if len(hull) >= 3 and (cross(hull, np.roll(hull, -1), z) >= 0).all():
        return 0.0
    return float(point_segment(z, hull, np.roll(hull, -1)).min())


def _inside(assembly: Assembly, positions: np.ndarray, sizes: Sizes, strap: Strap) -> set[int]:
    """The pins the sheave holds inside, clear of the strap: at its part's other joints, within
    its radius less the hole radius and clearance. Both are joints of one part, so the distance
    never changes."""
    margin = sizes.hole_diameter / 2 + sizes.clearance
    centre, sheave = positions[strap.joint], assembly.parts[strap.sheave_of].joints
    room = strap.radius * (1 + 1e-9) - margin
    return {k for k, pin in enumerate(assembly.pins)
            if pin.joint in sheave and pin.joint != strap.joint and strap.part not in pin.members
            and np.linalg.norm(positions[pin.joint] - centre) <= room}  # fmt: skip


def _near(conflicts: Conflicts, strap: Strap) -> set[int]:
    return {k for k, near in enumerate(conflicts.blocked) if strap.part in near}


class _Swept:
    """What every strap choice reads from the sweep, reckoned once: from each sheave's centre
    (`joints`) the least distance to each part's outline and to each joint, and the largest
    step of a joint between two angles."""

    def __init__(self, assembly: Assembly, paths: np.ndarray, joints: list[int]):
        points, owner, ends = outlines(assembly, paths)
        start, end = points[ends[:, 0]], points[ends[:, 1]]
        centres = points[joints]
        to_edges = least_distances(centres, centres, start, end, to_segment)  # (S, E)
        self.row = {j: k for k, j in enumerate(joints)}
        self.to_part = np.full((len(joints), len(assembly.parts)), np.inf)
        np.minimum.at(self.to_part, (np.arange(len(joints))[:, None], owner[None]), to_edges)
        self.to_joint = np.abs(centres[:, None] - points[None]).min(-1)  # (S, N)
        self.step = largest_step(paths)
        self.positions = paths[:, 0]


def _with_straps(
    assembly: Assembly, conflicts: Conflicts, swept: _Swept, sizes: Sizes, chosen: tuple
) -> Conflicts:
    """The conflicts with each chosen part's outline grown by its sheave's disc: other parts
    and the sheaves of other straps keep a width and the clearance from it, other pins their
    reach; the pins it frees are no longer kept off its layer."""
    reach = (sizes.link_width + sizes.hole_diameter) / 2 + sizes.clearance + swept.step
    distance, blocked = conflicts.distance.copy(), [list(b) for b in conflicts.blocked]
    for strap in chosen:
        row, a = swept.row[strap.joint], strap.part
        grown = swept.to_part[row] - strap.radius
        grown[[0, a]] = np.inf  # the ground's plates have layers of their own
        distance[a] = np.minimum(distance[a], grown)
        distance[:, a] = distance[a]
        for other in chosen:
            if other.part != a:
                apart = swept.to_joint[row, other.joint] - strap.radius - other.radius
                distance[a, other.part] = min(distance[a, other.part], apart)
                distance[other.part, a] = distance[a, other.part]
        inside = _inside(assembly, swept.positions, sizes, strap)
        for k, pin in enumerate(assembly.pins):
            if k in inside:
                blocked[k] = [q for q in blocked[k] if q != a]
            elif (
                a not in pin.members
                and a not in blocked[k]
                and swept.to_joint[row, pin.joint] - strap.radius < reach
            ):
                blocked[k].append(a)
    near = distance < sizes.link_width + sizes.clearance + swept.step
    np.fill_diagonal(near, False)
    near[0], near[:, 0] = False, False
    return replace(conflicts, parts=near, blocked=blocked, distance=distance)


def _layered(
    assembly: Assembly, conflicts: Conflicts, sizes: Sizes, shafts: Collection[int] = ()
) -> Layout | None:
    """Layers with every ground pin whole, else held from both plates but `shafts`; None if
    neither. The stubs' search goes first: it is looser than any whole layering, so where it
    finds none (as for most strap choices) the whole pins' search is spared."""
    try:
        held = stack_layers(assembly, conflicts, sizes, stubs=True, whole=shafts)
    except NoFlatLayers:
        return None
    try:
        return stack_layers(assembly, conflicts, sizes)
    except NoFlatLayers:
        return held


def _passing(
    assembly: Assembly, positions: np.ndarray, sizes: Sizes, layout: Layout, strap: Strap
) -> Strap:
    """The strap with the pins (rods) that cross its layer through its sheave."""
    layer = int(layout.layers[strap.part])
    spans = {k: [span] for k, span in enumerate(layout.pin_spans)}
    for k, span in layout.cover_stubs.items():
        spans[k].append(span)
    passing = tuple(sorted(k for k in _inside(assembly, positions, sizes, strap)
                           if any(lo <= layer <= hi for lo, hi in spans[k])))  # fmt: skip
    return replace(strap, passing=passing)
