"""Plates split into arms on a shaft, ground pins held by brackets or as stubs from both plates:
for mechanisms no flat layering builds.

In some mechanisms a part crosses, near its own joints, the pins of parts that turn about
them: typically a ternary plate whose two couplers each sweep, in the plate's frame, a whole
disc round their joint, covering the other's pin. Or three ground pivots each have a part
that sweeps over the other two, so no order of the stack lets every ground pin reach the base
or the cover. Then no order of flat layers keeps every pin clear, and neither narrower nor bent
links change that. Two constructions, in any combination, do:

- a plate (a part of three or more joints) is cut into arms, one plate per joint besides a
  shaft joint, all fixed on the pin at the shaft joint (the shaft; at a joint no other part
  shares, a pin of the plate's own), so each part that turns about the plate's other joints
  can have its arm on its own side of the stack;
- a ground pin is held by a bracket: a ground plate on a layer inside the stack with a hole for
  the pin, so the pin need not reach the base or the cover through the parts between. The
  bracket's arm runs straight out from the pivot to a post beyond everything the mechanism
  sweeps, which stands in the base plate (or hangs from the cover); the direction is the one
  whose arm the fewest pin paths and parts cross.

The arms, brackets and posts are layered like any other parts and pins: a bracket is a static
link from the pivot to the post, the post a pin of the ground at a point that never moves, and
the layer search keeps every part clear of them. Here the parts of a ground pin may also be
held from both plates (`layers.stack_layers`, stubs), except at a split part's shaft, which
stays whole. The clearances of every candidate (each plate whole and its arms for each shaft,
a bracket in each direction at each ground pin) are swept once; each choice is layered from its
share of them, the fewest brackets first, then the fewest split plates. A choice is not
searched when the same split plates with no ground pins at all (a looser problem than any
bracket, base, cover or stubs) are proved not to layer.
"""

from __future__ import annotations

from dataclasses import replace
from itertools import combinations, product

import numpy as np

from .layers import (
    Arm,
    Bracket,
    Conflicts,
    Layout,
    NoFlatLayers,
    Shaft,
    find_conflicts,
    stack_layers,
)
from .options import Sizes
from .parts import Assembly, Part, Pin

DIRECTIONS = 16  # directions tried for a bracket's arm
POST_MARGIN = 2.0  # link widths between the post and the farthest point the mechanism sweeps
MAX_SEARCHES = 300  # layer searches per width before the construction gives up


def braced_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with some plates split into arms on a shaft and some ground pins held by
    brackets. ValueError when no choice layers within MAX_SEARCHES layer searches."""
    ground = tuple(pin.joint for pin in assembly.pins if 0 in pin.members)
    plates = [q for q, part in enumerate(assembly.parts) if part.kind == "plate"]
    union, extended, roles, posts = _candidates(assembly, paths, sizes, ground)
    conflicts = find_conflicts(union, extended, sizes)
    bracket = _best_brackets(conflicts, roles)

    def layered(split: dict[int, int], held: tuple[int, ...], relaxed: bool = False):
        keep = [q for q, role in enumerate(roles)
                if (role[0] == "part" and role[1] not in split)
                or (role[0] == "arm" and split.get(role[1]) == role[2])
                or q in [bracket[g] for g in held]]  # fmt: skip
        chosen, share = _subset(union, conflicts, keep, held, ground if relaxed else ())
        arms = [sum(roles[keep[m]][0] == "arm" for m in pin.members) for pin in chosen.pins]
        shafts = [k for k, count in enumerate(arms) if count >= 2]  # stay whole at the ground
        return stack_layers(chosen, share, sizes, stubs=True, whole=shafts), keep, chosen

    try:  # every plate left out, no ground pin at all: looser than any choice
        layered({q: -1 for q in plates}, (), relaxed=True)
    except NoFlatLayers as exc:
        if exc.proved:
            raise
    shafts = [[None, *assembly.parts[q].joints] for q in plates]
    picks = product(*shafts)
    splits = [{q: s for q, s in zip(plates, pick) if s is not None} for pick in picks]
    splits = sorted((s for s in splits if len(set(s.values())) == len(s)), key=len)
    loose: dict[int, bool | None] = {}  # a split layers with no ground pins (None: unknown)
    searches, refusal = 1, None
    helds = [c for r in range(len(ground) + 1) for c in combinations(ground, r)]
    for bound in (True, None):  # the splits that layer loose first, then those the search gave up
        for held, (k, split) in product(helds, enumerate(splits)):
            if searches >= MAX_SEARCHES:
                break
            if k not in loose:
                searches += 1
                try:
                    layered(split, (), relaxed=True)
                    loose[k] = True
                except NoFlatLayers as exc:
                    loose[k], refusal = False if exc.proved else None, refusal or exc
            if loose[k] is not bound:
                continue
            searches += 1
            try:
                layout, keep, chosen = layered(split, held)
            except ValueError as exc:
                refusal = refusal or exc
                continue
            return _real(assembly, layout, chosen, [roles[q] for q in keep], posts, len(paths))
    raise refusal or ValueError("no split plates or brackets layer within the search")


def _candidates(
    assembly: Assembly, paths: np.ndarray, sizes: Sizes, ground: tuple[int, ...]
) -> tuple[Assembly, np.ndarray, list[tuple], np.ndarray]:
    """Every candidate part as the layer search sees it: the real parts, every plate's arms for
    each shaft joint (a link from the shaft to one more joint), and a bracket for each ground
    pin and direction (a static link from the pivot to its post, a point appended to the
    paths). The pins are those of the real assembly with every candidate at their joint for
    members, then a shaft at each plate joint no pin is at (it lapses unless the plate is split
    there), then each post, a pin of the ground. Returns it, the extended paths, each
    candidate's role (("part", q), ("arm", q, shaft) or ("bracket", joint, post)) and the
    posts (B, 2)."""
    parts, roles = list(assembly.parts), [("part", q) for q in range(len(assembly.parts))]
    for q, part in enumerate(assembly.parts):
        for shaft in part.joints if part.kind == "plate" else ():
            for j in (j for j in part.joints if j != shaft):
                parts.append(Part(f"{part.name}_arm{shaft}_{j}", "link", (shaft, j)))
                roles.append(("arm", q, shaft))
    angles = np.arange(DIRECTIONS) * (2 * np.pi / DIRECTIONS)
    circle = np.stack([np.cos(angles), np.sin(angles)], -1)
    margin = POST_MARGIN * sizes.link_width
    reach = [np.linalg.norm(paths - paths[g, 0], axis=-1).max() + margin for g in ground]
    posts = np.concatenate([paths[g, 0] + r * circle for g, r in zip(ground, reach)])
    first = len(paths)
    for k, g in enumerate(np.repeat(ground, DIRECTIONS).tolist()):
        parts.append(Part(f"ground_bracket{k}", "link", (g, first + k)))
        roles.append(("bracket", g, k))
    pins = []
    for pin in assembly.pins:
        members = [0] * (0 in pin.members)
        members += [q for q, part in enumerate(parts) if q and pin.joint in part.joints]
        pins.append(Pin(pin.name, pin.joint, members[0], tuple(members)))
    pinned = {pin.joint for pin in assembly.pins}
    for q, part in enumerate(assembly.parts):  # a shaft where no pin is: the split part's own
        for j in (j for j in part.joints if j not in pinned) if part.kind == "plate" else ():
            members = tuple(k for k, other in enumerate(parts) if j in other.joints)
            pins.append(Pin(f"shaft_{j}", j, q, members))
    brackets = [q for q, role in enumerate(roles) if role[0] == "bracket"]
    pins += [Pin(f"post{k}", first + k, 0, (0, q)) for k, q in enumerate(brackets)]
    still = np.repeat(posts[:, None], paths.shape[1], 1)
    return Assembly(parts, [], pins, []), np.concatenate([paths, still]), roles, posts


def _best_brackets(conflicts: Conflicts, roles: list[tuple]) -> dict[int, int]:
    """The bracket candidate of each ground pin whose arm the fewest pin paths, then real
    parts, come near."""
    real = np.array([role[0] == "part" for role in roles])
    best: dict[int, tuple] = {}
    for q, role in enumerate(roles):
        if role[0] == "bracket":
            near = sum(q in parts for parts in conflicts.blocked)
            score = (near, int(conflicts.parts[q, real].sum()), q)
            best[role[1]] = min(best.get(role[1], score), score)
    return {g: score[2] for g, score in best.items()}


def _subset(
    union: Assembly,
    conflicts: Conflicts,
    keep: list[int],
    free: tuple[int, ...],
    dropped: tuple[int, ...] = (),
) -> tuple[Assembly, Conflicts]:
    """The assembly and conflicts of the candidates `keep` (the ground first): pins keep the
    members and blocking parts that are kept, and lapse with fewer than two members. The pins
    at the joints `free` are not held by the ground (a bracket holds them); those at the joints
    `dropped` are left out (a bound: held in any way at all)."""
    index = {q: k for k, q in enumerate(keep)}
    pins, blocked = [], []
    for pin, near in zip(union.pins, conflicts.blocked):
        if pin.joint in dropped:
            continue
        members = tuple(index[q] for q in pin.members
                        if q in index and not (q == 0 and pin.joint in free))  # fmt: skip
        if len(members) >= 2:
            pins.append(replace(pin, hub=members[0], members=members))
            blocked.append([index[q] for q in near if q in index])
    sub = np.ix_(keep, keep)
    return (Assembly([union.parts[q] for q in keep], [], pins, []),
            Conflicts(conflicts.parts[sub], blocked, conflicts.distance[sub]))  # fmt: skip


def _real(
    assembly: Assembly,
    layout: Layout,
    chosen: Assembly,
    roles: list[tuple],
    posts: np.ndarray,
    first: int,
) -> Layout:
    """The layout of the real parts from that of the chosen candidates (`roles`, in the
    layout's order): a split part's layer is its lowest arm's, its arms listed with their
    layers, its shaft where no pin was; the brackets, and where their posts go (joint
    `first + k` for post k)."""
    layers = np.zeros(len(assembly.parts), int)
    arms: dict[int, list[Arm]] = {}
    brackets = []
    for part, role, layer in zip(chosen.parts, roles, layout.layers.tolist()):
        if role[0] == "bracket":
            point = (float(posts[role[2], 0]), float(posts[role[2], 1]))
            brackets.append(Bracket(role[1], point, layer, first + role[2] in layout.top_joints))
            continue
        if role[0] == "arm":
            arms.setdefault(role[1], []).append(Arm(part.joints, layer))
        layers[role[1]] = min(layers[role[1]] or layer, layer)
    split = {role[2]: role[1] for role in roles if role[0] == "arm"}
    shafts = tuple(Shaft(split[pin.joint], pin.joint, span)
                   for pin, span in zip(chosen.pins, layout.pin_spans)
                   if pin.name.startswith("shaft_"))  # fmt: skip
    top = tuple(j for j in layout.top_joints if j < first)
    return Layout(layers, layout.pin_spans[: len(assembly.pins)], top, layout.count,
                  layout.min_gap, layout.minimal, arms={p: tuple(a) for p, a in arms.items()},
                  brackets=tuple(brackets), shafts=shafts,
                  cover_stubs={k: span for k, span in layout.cover_stubs.items()
                               if k < len(assembly.pins)})  # fmt: skip
