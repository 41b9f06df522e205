"""The crank on a turntable: a disc that turns in a ring, with no pin at the motor's pivot.

In a few mechanisms no construction holds the motor's pivot: the parts that pass over it lie
on both sides of the crank in every order the other pins allow, so the motor's shaft, from
the base or the cover, would cross one of them. A turntable needs no shaft. The crank is made
a disc round the motor's pivot, wide enough to hold every one of its pins, and it turns in the
bore of a ground ring on its own layer (a slewing ring), held by posts from the base beyond
everything the mechanism sweeps; the motor drives the disc at its rim. Nothing but the crank's
own pins may cross that layer, so the disc splits the stack: what lies below it and what lies
above meet only at the crank's pins. Other parts at the motor's pivot keep their pin, as a stub
from the base or the cover that stops short of the disc.

The search is the forks' (`forked.fork_search`: whole parts first, then forks, none at the
crank), on the split plates' candidates with the crank taken off the motor's pin and made the
disc: it has its layer to itself, and every pin but its own keeps off that layer.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .braced import swept_candidates
from .forked import drivable, fork_search
from .framed import posts_beyond
from .layers import Conflicts, Layout, NoFlatLayers, Turntable, stack_layers
from .options import Sizes
from .parts import Assembly


def turntable_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with the crank a disc turning in a ground ring (NoFlatLayers where none
    layers): whole parts first, then forked ones."""
    crank, motor = assembly.crank.child, assembly.crank.joint
    union, roles, posts, conflicts = swept_candidates(assembly, paths, sizes)
    searched = _off_pivot(assembly, crank, motor, {crank})
    arms = {u for u, role in enumerate(roles) if role[0] == "arm" and role[1] == crank}
    union = _off_pivot(union, crank, motor, {crank, *arms})
    conflicts = _on_own_layer(union, conflicts, crank)
    real = len(assembly.parts)
    whole = replace(conflicts, parts=conflicts.parts[:real, :real],
                    distance=conflicts.distance[:real, :real],
                    blocked=[[q for q in near if q < real]
                             for near in conflicts.blocked[: len(assembly.pins)]])  # fmt: skip
    try:
        layout = stack_layers(searched, whole, sizes, stubs=True)
    except NoFlatLayers:
        layout = fork_search(searched, (union, roles, posts, conflicts), len(paths), sizes,
                             lambda a, fork: fork[0] != crank and drivable(a, fork),
                             brackets=False)  # fmt: skip
    positions = paths[list(assembly.parts[crank].joints), 0] - paths[motor, 0]
    radius = float(np.linalg.norm(positions, axis=1).max()) + sizes.link_width / 2
    table = Turntable(crank, motor, int(layout.layers[crank]), radius,
                      radius + sizes.clearance, posts_beyond(paths, motor, sizes))  # fmt: skip
    return replace(layout, turntable=table)


def _off_pivot(assembly: Assembly, crank: int, motor: int, taken: set[int]) -> Assembly:
    """The assembly as searched: the crank (and its candidates `taken`) off the pin at the
    motor's pivot and without that joint (a pin left to the ground alone holds nothing)."""
    parts = list(assembly.parts)
    parts[crank] = replace(parts[crank], joints=tuple(j for j in parts[crank].joints if j != motor))
    pins = []
    for pin in assembly.pins:
        if pin.joint == motor and not pin.name.startswith("post"):
            members = tuple(m for m in pin.members if m not in taken)
            pin = replace(pin, hub=members[0], members=members)
        pins.append(pin)
    return replace(assembly, parts=parts, pins=pins)


def _on_own_layer(union: Assembly, conflicts: Conflicts, crank: int) -> Conflicts:
    """The conflicts with the crank a disc in a ring that fills its layer: no other part shares
    it, and every pin but the crank's own (and the ground's posts) keeps off it."""
    near = conflicts.parts.copy()
    near[crank, 1:] = near[1:, crank] = True
    near[crank, crank] = False
    blocked = [near_pin if crank in pin.members or pin.name.startswith("post")
               or crank in near_pin else [*near_pin, crank]
               for pin, near_pin in zip(union.pins, conflicts.blocked)]  # fmt: skip
    return replace(conflicts, parts=near, blocked=blocked)
