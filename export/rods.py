"""Pins as made: one rod per pin, two for a ground pin whose parts are held from both the
base and the cover (stubs, `layers.stack_layers`), coaxial rods apart in z where a part forks
(`forked`)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, replace
from string import ascii_lowercase

from .layers import Layout
from .parts import Assembly


@dataclass(frozen=True)
class Rod:
    """A pin as made: a rod fixed in part `hub` over the layers `span`, through the holes of
    `members` (hub included)."""

    name: str
    joint: int
    hub: int
    members: tuple[int, ...]
    span: tuple[int, int]


def pin_rods(assembly: Assembly, layout: Layout) -> list[Rod]:
    """Every pin's rod. A ground pin whose parts are held from both plates (`cover_stubs`: pin
    index to the span of its stub from the cover) is two: `pin_spans` standing in the base, its
    stub (`<name>_top`) hanging from the cover, each through the parts within its span. A pin
    where a part forks (`forks`) is coaxial rods fixed in the forked part, `<name>a`,
    `<name>b`, ... bottom up, each with the parts turning on it (a joint has under 20). A
    part on a turntable (or on a ground ring, at another ground pivot) is on no pin at its
    pivot: that pin is only there where other parts turn on it. Where the crank is cut in two
    (`drive`), the motor's stubs are fixed in its halves and turn in the base and the cover."""
    rods = []
    tabled = {table.joint: set() for table in layout.turntables}
    for table in layout.turntables:
        tabled[table.joint].add(table.part)
    for k, pin in enumerate(assembly.pins):
        if pin.joint in tabled:  # the turntables' parts turn in their rings instead
            members = tuple(m for m in pin.members if m not in tabled[pin.joint])
            if not any(members):
                continue
            pin = replace(pin, hub=pin.hub if pin.hub in members else members[0], members=members)
        if k in layout.forks:
            fork = layout.forks[k]
            hubs = fork.hubs or (fork.part,) * len(fork.rods)
            for letter, hub, (parts, span) in zip(ascii_lowercase, hubs, fork.rods):
                rods.append(Rod(f"{pin.name}{letter}", pin.joint, hub, (hub, *parts), span))
            continue
        if k not in layout.cover_stubs:
            rods.append(Rod(pin.name, pin.joint, pin.hub, pin.members, layout.pin_spans[k]))
            continue
        stubs = {pin.name: layout.pin_spans[k], f"{pin.name}_top": layout.cover_stubs[k]}
        driven = layout.drive is not None and k == layout.drive.pin
        hubs = (assembly.crank.child, layout.drive.upper) if driven else (pin.hub, pin.hub)
        for hub, (name, (lo, hi)) in zip(hubs, stubs.items()):
            inside = [m for m in pin.members if lo <= _layer_at(layout, m, pin.joint) <= hi]
            members = tuple(m for m in pin.members if m in (hub, 0) or m in inside)
            rods.append(Rod(name, pin.joint, hub, members, (lo, hi)))
    return rods


def _layer_at(layout: Layout, part: int, joint: int) -> int:
    """The layer of a part's plate at one of its joints (a split part's arm there)."""
    arms = [arm.layer for arm in layout.arms.get(part, ()) if joint in arm.joints]
    return arms[0] if arms else int(layout.layers[part])


def keyed(arms: Iterable[tuple[int, int]]) -> set[int]:
    """The joints where two or more arms of a split part meet: the pins there are fixed in the
    arms, which so turn as one rigid part."""
    count = Counter(j for arm in arms for j in arm)
    return {j for j, n in count.items() if n >= 2}
