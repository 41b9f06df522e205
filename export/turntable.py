"""Parts at the motor's pivot on turntables: discs or rings that turn in ground rings, with no
pin at the pivot.

In a few mechanisms no construction holds the motor's pivot: the parts that pass over it lie
on both sides of the crank in every order the other pins allow, so the motor's shaft, from
the base or the cover, would cross one of them. A turntable needs no shaft. The crank is made
a disc round the motor's pivot, wide enough to hold every one of its pins, and it turns in the
bore of a ground ring on its own layer (a slewing ring), held by posts from the base beyond
everything the mechanism sweeps; the motor drives the disc at its rim. Nothing but the crank's
own pins may cross that layer, so the disc splits the stack: what lies below it and what lies
above meet only at the crank's pins. Other parts at the motor's pivot keep their pin, as a stub
from the base or the cover that stops short of the disc.

Where that does not layer, the other parts at the pivot go on turntables instead, each a ring
(a disc with a hole, as far in as its nearest joint allows) in a ground ring of its own, on
shared posts, round the crank's shaft. A pin whose path stays inside a ring's hole may cross
its layer, as the crank's shaft does. (With the crank a disc as well, the bounds built no more
than this: docs/benchmarks.md.)

The search is the forks' (`forked.fork_search`: whole parts first, then forks, none of a part
on a turntable; a bracket only for the rings), on the split plates' candidates with those
parts taken off the motor's pin: each has its layer to itself, and every pin but its own, and
those inside its hole, keeps off that layer. With the crank alone on a turntable, the straps'
search (`strapped.strap_search`) comes last: some parts (never the crank) may turn round
sheaves as straps, so the pins within a sheave cross its strap's layer. One strap or two are
tried here; more, round a core of straps, only after every other construction
(`turntable_core_layers`), so that several straps with no turntable come first.
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial

import numpy as np

from .braced import swept_candidates
from .forked import drivable, fork_search
from .framed import posts_beyond
from .layers import Conflicts, Layout, NoFlatLayers, Turntable, largest_step, stack_layers
from .options import Sizes
from .parts import Assembly
from .strapped import strap_search


def turntable_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with parts at the motor's pivot on turntables (NoFlatLayers where none layers):
    the crank alone, then the others round its shaft."""
    crank, motor = assembly.crank.child, assembly.crank.joint
    pivot = next(pin for pin in assembly.pins if pin.joint == motor)
    others = {m for m in pivot.members if m and m != crank}
    try:
        return _on_turntables(assembly, paths, sizes, {crank}, brackets=False)
    except NoFlatLayers:
        if not others:
            raise
    return _on_turntables(assembly, paths, sizes, others, brackets=True)


def turntable_core_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with the crank alone on a turntable and several parts straps round a core of
    them, the last construction tried (NoFlatLayers where none layers)."""
    return _on_turntables(assembly, paths, sizes, {assembly.crank.child}, False, core=True)


def _on_turntables(
    assembly: Assembly,
    paths: np.ndarray,
    sizes: Sizes,
    taken: set[int],
    brackets: bool,
    core: bool = False,
) -> Layout:
    """Layers with the parts `taken` on turntables, whole parts first, then forked ones (with
    one ground pin on a bracket where `brackets`), then, for the crank alone (no `brackets`),
    one or two parts made straps; with `core`, only several straps round a core."""
    crank, motor = assembly.crank.child, assembly.crank.joint
    union, roles, posts, conflicts = swept_candidates(assembly, paths, sizes)
    searched = _off_pivot(assembly, motor, taken)
    arms = {u for u, role in enumerate(roles) if role[0] == "arm" and role[1] in taken}
    union = _off_pivot(union, motor, taken, arms)
    radii = {p: _radii(assembly, paths, p) for p in taken}  # (nearest, farthest) joint
    holes = {p: 0.0 if p == crank else _hole(radii[p][0], sizes) for p in taken}
    inside = {p: _inside(paths, motor, sizes, hole) for p, hole in holes.items()}
    real = len(assembly.parts)
    plain = replace(conflicts, parts=conflicts.parts[:real, :real],
                    distance=conflicts.distance[:real, :real],
                    blocked=[[q for q in near if q < real]
                             for near in conflicts.blocked[: len(assembly.pins)]])  # fmt: skip
    conflicts = _on_own_layers(union, conflicts, inside)
    own = partial(_on_own_layers, searched, inside=inside)  # the real parts' rules
    straps = partial(strap_search, searched, plain, paths, sizes, then=own, whole=taken)
    try:
        if core:  # several straps round a core: the last construction tried
            layout = straps(core=True)
        else:
            layout = stack_layers(searched, own(plain), sizes, stubs=True)
    except NoFlatLayers:
        if core:
            raise
        try:
            layout = fork_search(searched, (union, roles, posts, conflicts), len(paths), sizes,
                                 lambda a, fork: fork[0] not in taken and drivable(a, fork),
                                 brackets=brackets)  # fmt: skip
        except NoFlatLayers:
            if brackets:  # the rings: with straps, the bounds built nothing more
                raise
            layout = straps()
    ring_posts = posts_beyond(paths, motor, sizes)
    tables = []
    for p in sorted(taken):
        radius = radii[p][1] + sizes.link_width / 2
        tables.append(Turntable(p, motor, int(layout.layers[p]), radius,
                                radius + sizes.clearance, ring_posts, holes[p]))  # fmt: skip
    return replace(layout, turntables=tuple(tables))


def _radii(assembly: Assembly, paths: np.ndarray, part: int) -> tuple[float, float]:
    """The distances of a part's nearest and farthest joints from the motor's pivot, which it
    turns about (so they hold over the sweep)."""
    motor = assembly.crank.joint
    joints = [j for j in assembly.parts[part].joints if j != motor]
    distance = np.linalg.norm(paths[joints, 0] - paths[motor, 0], axis=1)
    return float(distance.min()), float(distance.max())


def _hole(nearest: float, sizes: Sizes) -> float:
    """The radius of a ring's hole: half a width inside its nearest joint (0: a disc, where
    that leaves no room for a pin)."""
    hole = nearest - sizes.link_width / 2
    return hole if hole > sizes.hole_diameter + 2 * sizes.clearance else 0.0


def _inside(paths: np.ndarray, motor: int, sizes: Sizes, hole: float) -> set[int]:
    """The joints whose pins stay inside a hole of that radius over the sweep, clear of its
    edge (the sweep's largest step to spare, as in `layers.find_conflicts`)."""
    if not hole:
        return set()
    reach = sizes.hole_diameter / 2 + sizes.clearance + largest_step(paths)
    far = np.linalg.norm(paths - paths[motor, :1], axis=-1).max(1)
    return set(np.flatnonzero(far < hole - reach).tolist())


def _off_pivot(
    assembly: Assembly, motor: int, taken: set[int], arms: set[int] = frozenset()
) -> Assembly:
    """The assembly as searched: the parts `taken` off the pin at the motor's pivot and without
    that joint (a pin left to the ground alone holds nothing), and their candidate `arms` off
    the pin too."""
    parts = list(assembly.parts)
    for p in taken:
        parts[p] = replace(parts[p], joints=tuple(j for j in parts[p].joints if j != motor))
    pins = []
    for pin in assembly.pins:
        if pin.joint == motor and not pin.name.startswith("post"):
            members = tuple(m for m in pin.members if m not in taken | arms)
            pin = replace(pin, hub=members[0], members=members)
        pins.append(pin)
    return replace(assembly, parts=parts, pins=pins)


def _on_own_layers(union: Assembly, conflicts: Conflicts, inside: dict[int, set[int]]) -> Conflicts:
    """The conflicts with each part of `inside` on a turntable whose ring fills its layer: no
    other part shares it, and every pin but its own, the ground's posts and the pins at the
    joints `inside[part]` (within its hole) keeps off it."""
    near = conflicts.parts.copy()
    blocked = [list(near_pin) for near_pin in conflicts.blocked]
    for part, passing in inside.items():
        near[part, 1:] = near[1:, part] = True
        near[part, part] = False
        for pin, near_pin in zip(union.pins, blocked):
            free = part in pin.members or pin.name.startswith("post") or pin.joint in passing
            if not free and part not in near_pin:
                near_pin.append(part)
    return replace(conflicts, parts=near, blocked=blocked)
