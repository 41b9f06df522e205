"""Split cranks on a shaft held by a ground bracket: for mechanisms no flat layering builds.

In some mechanisms the parts at the crank cross each other's pins near their joints: typically
a ternary crank whose two couplers each sweep, in the crank's frame, a whole disc round their
joint, covering the other's pin and the ground pivot. Then no order of flat layers keeps every
pin clear, and neither narrower nor bent links change that. Three constructions together do:

- the crank is cut into arms, one plate per joint besides a shaft joint, all fixed on the pin
  at the shaft joint (the shaft), so each coupler can have an arm on its own side of the stack;
- the ground pivot is held by a bracket: a ground plate on a layer inside the stack with a hole
  for the pivot's pin, so that pin need not reach the base or the cover through the couplers;
- the bracket's arm runs straight out from the pivot to a post beyond everything the
  mechanism sweeps, which stands in the base plate (or hangs from the cover); the direction is
  the one whose arm the fewest pin paths and parts cross.

The split parts, the bracket and its post are layered like any other parts and pins: the
bracket is a static link from the pivot to the post, the post a pin of the ground at a point
that never moves, and the layer search keeps every part clear of them. The clearances of every
candidate (the whole crank, its arms for each shaft, a bracket in each direction) are swept
once, and each choice is layered from its share of them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .layers import Arm, Bracket, Conflicts, Layout, find_conflicts, stack_layers
from .options import Sizes
from .parts import CRANK, Assembly, Part, Pin

DIRECTIONS = 16  # directions tried for a bracket's arm
POST_MARGIN = 2.0  # link widths between the post and the farthest point the mechanism sweeps


def braced_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with the crank's ground pivot held by a bracket and the crank, when it is a plate,
    cut into arms on a shaft at one of its pinned joints (the pivot first; a binary crank stays
    whole). ValueError when none layers."""
    crank = next(h for h in assembly.hinges if h.name == CRANK)
    pivot, part = crank.joint, assembly.parts[crank.child]
    pinned = {pin.joint for pin in assembly.pins}
    shafts = [pivot, *(j for j in part.joints if j != pivot and j in pinned)]
    if part.kind != "plate":
        shafts = []  # a binary crank is one arm already
    rest = _rest(assembly, find_conflicts(assembly, paths, sizes), crank.child, pivot)
    stack_layers(*rest, sizes)  # or ValueError, at once: then no choice below layers either
    union, extended, owners, posts = _candidates(assembly, paths, sizes, crank.child, pivot, shafts)
    conflicts = find_conflicts(union, extended, sizes)
    brackets = [q for q, owner in enumerate(owners) if owner < 0]
    scores = [(sum(q in b for b in conflicts.blocked), int(conflicts.parts[q].sum()), k)
              for k, q in enumerate(brackets)]  # fmt: skip
    direction = min(scores)[2]
    bracket, real = brackets[direction], len(assembly.parts)
    refusal = None
    for shaft in shafts or [None]:
        keep = [q for q, owner in enumerate(owners)
                if (owner >= 0 and q < real and (q != crank.child or shaft is None))
                or (q >= real and owner == crank.child and union.parts[q].joints[0] == shaft)
                or q == bracket]  # fmt: skip
        chosen, share = _subset(union, conflicts, keep)
        try:
            layout = stack_layers(chosen, share, sizes)
        except ValueError as exc:
            refusal = refusal or exc
            continue
        return _real(assembly, layout, chosen, [owners[q] for q in keep], posts[direction])
    raise refusal


def _rest(
    assembly: Assembly, conflicts: Conflicts, crank: int, pivot: int
) -> tuple[Assembly, Conflicts]:
    """The mechanism without its crank, the pivot's pin not held by the ground: what every
    choice of arms and bracket leaves as it is, with fewer constraints than any of them."""
    pins = [replace(pin, members=tuple(m for m in pin.members if m)) if pin.joint == pivot
            else pin for pin in assembly.pins]  # fmt: skip
    keep = [q for q in range(len(assembly.parts)) if q != crank]
    return _subset(replace(assembly, pins=pins), conflicts, keep)


def _candidates(
    assembly: Assembly, paths: np.ndarray, sizes: Sizes, crank: int, pivot: int, shafts: list
) -> tuple[Assembly, np.ndarray, list[int], np.ndarray]:
    """Every candidate part as the layer search sees it: the real parts, the crank's arms for
    each shaft (a link from the shaft to one more joint), and a bracket for each direction (a
    static link from the pivot to its post, a point appended to the paths). The pins are those
    of the real assembly with every candidate at their joint for members (the pivot's held by
    the brackets, not by the ground), then each post, a pin of the ground. Returns it, the
    extended paths, the real part of every candidate (-1 for a bracket) and the posts (D, 2)."""
    parts, owners = list(assembly.parts), list(range(len(assembly.parts)))
    for shaft in shafts:
        for j in assembly.parts[crank].joints:
            if j != shaft:
                parts.append(Part(f"{assembly.parts[crank].name}_arm{j}", "link", (shaft, j)))
                owners.append(crank)
    centre = paths[pivot, 0]
    radius = np.linalg.norm(paths - centre, axis=-1).max() + POST_MARGIN * sizes.link_width
    angles = np.arange(DIRECTIONS) * (2 * np.pi / DIRECTIONS)
    posts = centre + radius * np.stack([np.cos(angles), np.sin(angles)], -1)
    first = len(paths)
    for k in range(DIRECTIONS):
        parts.append(Part(f"ground_bracket{k}", "link", (pivot, first + k)))
        owners.append(-1)
    pins = []
    for pin in assembly.pins:
        members = [q for q, part in enumerate(parts) if q and pin.joint in part.joints]
        if pin.joint != pivot and 0 in pin.members:
            members.insert(0, 0)
        pins.append(Pin(pin.name, pin.joint, members[0], tuple(members)))
    for k in range(DIRECTIONS):
        pins.append(Pin(f"post{k}", first + k, 0, (0, len(parts) - DIRECTIONS + k)))
    still = np.repeat(posts[:, None], paths.shape[1], 1)
    return Assembly(parts, [], pins, []), np.concatenate([paths, still]), owners, posts


def _subset(union: Assembly, conflicts: Conflicts, keep: list[int]) -> tuple[Assembly, Conflicts]:
    """The assembly and conflicts of the candidates `keep` (the ground first): pins keep the
    members and blocking parts that are kept, and lapse with fewer than two members."""
    index = {q: k for k, q in enumerate(keep)}
    pins, blocked = [], []
    for pin, near in zip(union.pins, conflicts.blocked):
        members = tuple(index[q] for q in pin.members if q in index)
        if len(members) >= 2:
            pins.append(replace(pin, hub=members[0], members=members))
            blocked.append([index[q] for q in near if q in index])
    sub = np.ix_(keep, keep)
    return (Assembly([union.parts[q] for q in keep], [], pins, []),
            Conflicts(conflicts.parts[sub], blocked, conflicts.distance[sub]))  # fmt: skip


def _real(
    assembly: Assembly, layout: Layout, virtual: Assembly, owners: list[int], post: np.ndarray
) -> Layout:
    """The layout of the real parts from the virtual one: a split part's layer is its lowest
    arm's, its arms listed with their layers; the bracket and where its post goes."""
    layers = np.zeros(len(assembly.parts), int)
    arms: dict[int, list[Arm]] = {}
    point = virtual.pins[-1].joint  # the post's
    for q, owner in enumerate(owners):
        joints, layer = virtual.parts[q].joints, int(layout.layers[q])
        if owner < 0:
            bracket = Bracket(joints[0], (float(post[0]), float(post[1])), layer,
                              point in layout.top_joints)  # fmt: skip
            continue
        if owner and virtual.parts[q].name != assembly.parts[owner].name:
            arms.setdefault(owner, []).append(Arm(joints, layer))
        layers[owner] = min(layers[owner] or layer, layer)
    top = tuple(j for j in layout.top_joints if j != point)
    return Layout(layers, layout.pin_spans[: len(assembly.pins)], top, layout.count,
                  layout.min_gap, layout.minimal, arms={p: tuple(a) for p, a in arms.items()},
                  brackets=(bracket,))  # fmt: skip
