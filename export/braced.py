"""Plates cut into arms, ground pins held by brackets or as stubs from both plates: for
mechanisms no flat layering builds.

In some mechanisms a part crosses, near its own joints, the pins of parts that turn about
them: typically a ternary plate whose two couplers each sweep, in the plate's frame, a whole
disc round their joint, covering the other's pin. Or three ground pivots each have a part
that sweeps over the other two, so no order of the stack lets every ground pin reach the base
or the cover. Then no order of flat layers keeps every pin clear, and neither narrower nor bent
links change that. Two constructions, in any combination, do:

- a plate (a part of three or more joints) is cut into arms, each a plate of its own joining
  two of its joints: one from a shaft joint to each other joint (a star), or else along the
  plate's own links, any tree of them (a crankshaft: a link turning on a crankpin between the
  two arms fixed on it), so each part that turns about the plate's joints can have its arm on
  its own side of the stack. Wherever arms meet, the pin is fixed in them (the shaft; at a
  joint no other part shares, a pin of the plate's own);
- a ground pin is held by a bracket: a ground plate on a layer inside the stack with a hole for
  the pin, so the pin need not reach the base or the cover through the parts between. The
  bracket's arm runs straight out from the pivot to a post beyond everything the mechanism
  sweeps, which stands in the base plate (or hangs from the cover); the direction is the one
  whose arm the fewest pin paths and parts cross.

The arms, brackets and posts are layered like any other parts and pins: a bracket is a static
link from the pivot to the post, the post a pin of the ground at a point that never moves, and
the layer search keeps every part clear of them. Here the parts of a ground pin may also be
held from both plates (`layers.stack_layers`, stubs), except at a split part's shaft, which
stays whole. The clearances of every candidate (each plate whole, an arm between each two of
its joints, a bracket in each direction at each ground pin) are swept once; each choice is
layered from its share of them, the fewest brackets first, then the fewest split plates,
stars first; only where no star layers are the cuts along the plates' own links searched,
with a search budget of their own. A choice is not searched when the same split plates with
no ground pins at all (a looser problem than any bracket, base, cover or stubs) do not layer.

Last of all the constructions, split plates and eccentric straps (`strapped`) are tried
together (`split_straps_layers`): in a few mechanisms a plate must be cut so that its arms lie
on both sides of a part, and a link must turn on a sheave so that a pin may cross its layer,
and neither alone layers. Each split, fewest first, gets the straps' own search, with no
bracket; an arm may be a strap too (bored round the sheave at one of its joints). And where
that fails, the same with the motor's shaft cut into stubs as well (`cut_crank_layers`, on
the splits that cut the crank at the motor): the crank's arms then lie on both sides of the
parts passing over its pivot, its two halves driven as one from outside the stack (`drive`);
there, many splits are first asked (exactly, and quickly) whether they layer with no strap.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import suppress
from dataclasses import replace
from itertools import combinations, islice, product

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
from .rods import keyed
from .strapped import strap_search

DIRECTIONS = 16  # directions tried for a bracket's arm
POST_MARGIN = 2.0  # link widths between the post and the farthest point the mechanism sweeps
MAX_SEARCHES = 300  # layer searches per width before the construction gives up
MAX_LINK_CUTS = 100  # and then for plates cut along their own links
MAX_LINK_SETS = 20_000  # sets of a plate's links tried as trees of arms
MAX_SPLIT_STRAPS = 16  # splits tried with straps (`split_straps_layers`); those built took 4
MAX_CUT_SPLITS = 4  # and with the crank cut too, of those splitting it at the motor; built: 2
MAX_CUT_SCREENED = 2_000  # and before those, splits asked exactly whether they layer strapless


def braced_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with some plates cut into arms and some ground pins held by brackets.
    ValueError when no choice layers within MAX_SEARCHES layer searches of stars, then
    MAX_LINK_CUTS of cuts along the plates' own links."""
    ground = tuple(pin.joint for pin in assembly.pins if 0 in pin.members)
    plates = [q for q, part in enumerate(assembly.parts) if part.kind == "plate"]
    union, roles, posts, conflicts = swept_candidates(assembly, paths, sizes)
    bracket = best_brackets(conflicts, roles)

    def layered(split: dict[int, tuple], held: tuple[int, ...], relaxed: bool = False):
        keep = _kept(roles, split, [bracket[g] for g in held])
        chosen, share = _subset(union, conflicts, keep, held, ground if relaxed else ())
        shafts = _shafts(chosen, [roles[q] for q in keep])
        layout = stack_layers(chosen, share, sizes, stubs=True, whole=shafts, fewest=not relaxed)
        return layout, keep, chosen

    # every plate left out, no ground pin at all: looser than any choice (NoFlatLayers if not)
    layered({q: () for q in plates}, (), relaxed=True)
    stars, ways = _cuts(assembly, plates, paths)
    helds = [c for r in range(len(ground) + 1) for c in combinations(ground, r)]
    found, refusal = _first(layered, lambda: _splits(stars), helds, MAX_SEARCHES, spent=1)
    if found is None:  # then cut along the plates' own links too, with a budget of its own

        def trees() -> Iterator[dict]:
            return (s for s in _splits(ways) if any(w not in stars[q] for q, w in s.items()))

        found, second = _first(layered, trees, helds, MAX_LINK_CUTS)
        refusal = refusal or second
    if found is not None:
        layout, keep, chosen = found
        return _real(assembly, layout, chosen, [roles[q] for q in keep], posts, len(paths))
    raise refusal or ValueError("no split plates or brackets layer within the search")


def split_straps_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with some plates cut into arms and some parts or arms made straps at once, for the
    few mechanisms neither builds alone (NoFlatLayers where none of the first MAX_SPLIT_STRAPS
    splits, stars and cuts along the plates' own links, the fewest split plates first, layers
    with one strap or two, or round a core of them: `strapped.strap_search`). No bracket:
    the stubs from base and cover hold the ground pins."""
    return _split_straps(assembly, paths, sizes, cut=False)


def cut_crank_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """`split_straps_layers` with the motor's shaft, too, cut into stubs from base and cover
    (the crank's halves turned as one from outside the stack, `drive`), on the splits that cut
    the crank at the motor: with it whole there, the search is the one that failed already."""
    return _split_straps(assembly, paths, sizes, cut=True)


def _split_straps(assembly: Assembly, paths: np.ndarray, sizes: Sizes, cut: bool) -> Layout:
    """split_straps_layers; cut: the motor's shaft may be cut, and strapless splits come first."""
    plates = [q for q, part in enumerate(assembly.parts) if part.kind == "plate"]
    union, roles, posts, conflicts = swept_candidates(assembly, paths, sizes)
    _, ways = _cuts(assembly, plates, paths)
    crank, motor = assembly.crank.child, assembly.crank.joint

    def worth(split: dict) -> bool:
        return bool(split) and (not cut or sum(motor in arm for arm in split.get(crank, ())) >= 2)

    def chosen_for(split: dict) -> tuple[Assembly, Conflicts, list[tuple], list[int]]:
        keep = _kept(roles, split, [])
        chosen, share = _subset(union, conflicts, keep, ())
        kept = [roles[q] for q in keep]
        driven = next(k for k, role in enumerate(kept)  # the crank, or its arm at the motor
                      if role[1] == crank and motor in chosen.parts[k].joints)  # fmt: skip
        chosen = replace(chosen, hinges=[replace(assembly.crank, child=driven)])
        shafts = [k for k in _shafts(chosen, kept) if not (cut and chosen.pins[k].joint == motor)]
        return chosen, share, kept, shafts

    for split in islice(filter(worth, _splits(ways)), MAX_CUT_SCREENED if cut else 0):
        chosen, share, kept, shafts = chosen_for(split)
        with suppress(NoFlatLayers):  # the first that layers with no strap
            layout = stack_layers(chosen, share, sizes, stubs=True, whole=shafts)
            return _real(assembly, layout, chosen, kept, posts, len(paths))
    for split in islice(filter(worth, _splits(ways)), MAX_CUT_SPLITS if cut else MAX_SPLIT_STRAPS):
        chosen, share, kept, shafts = chosen_for(split)
        for core in (False, True):
            try:
                layout = strap_search(chosen, share, paths, sizes, core=core, shafts=shafts)
            except NoFlatLayers:
                continue
            if any(k >= len(assembly.pins) for strap in layout.straps for k in strap.passing):
                break  # a split part's own shaft would cross a sheave: the next split
            real = _real(assembly, layout, chosen, kept, posts, len(paths))
            straps = [replace(strap, part=kept[strap.part][1], sheave_of=kept[strap.sheave_of][1],
                              arm=kept[strap.part][2] if kept[strap.part][0] == "arm" else ())
                      for strap in layout.straps]  # fmt: skip
            return replace(real, straps=tuple(straps))
    raise NoFlatLayers("no split plates tried layer with straps")


def _cuts(assembly: Assembly, plates: list[int], paths: np.ndarray) -> tuple[dict, dict]:
    """Each plate's ways to be cut: the stars, and the stars then the trees of its own links."""
    stars = {q: _stars(assembly.parts[q]) for q in plates}
    return stars, {q: stars[q] + _own_trees(assembly.parts[q], stars[q], paths[:, 0])
                   for q in plates}  # fmt: skip


def _kept(roles: list[tuple], split: dict[int, tuple], brackets: list[int]) -> list[int]:
    """The candidates of a choice: the parts not split, the arms of those `split` (each
    plate's cut), and the `brackets` candidates."""
    return [q for q, role in enumerate(roles)
            if (role[0] == "part" and role[1] not in split)
            or (role[0] == "arm" and role[2] in split.get(role[1], ()))
            or q in brackets]  # fmt: skip


def _shafts(chosen: Assembly, roles: list[tuple]) -> list[int]:
    """The pins of `chosen` where two arms meet: they stay whole at the ground (the shaft a
    split part's arms are fixed on)."""
    arms = [sum(roles[m][0] == "arm" for m in pin.members) for pin in chosen.pins]
    return [k for k, count in enumerate(arms) if count >= 2]


def _first(
    layered: Callable,
    splits: Callable[[], Iterator[dict]],
    helds: list[tuple],
    budget: int,
    spent: int = 0,
) -> tuple[tuple | None, ValueError | None]:
    """The first of `layered(split, held)` that layers, over the ground pins `helds` on brackets
    (the fewest first) and `splits()`, within `budget` layer searches (`spent` of them
    already), trying only the splits that layer with no ground pins at all (a looser problem
    than any bracket, base, cover or stubs). With it, the first refusal."""
    loose: dict[int, bool] = {}  # a split layers with no ground pins
    searches, refusal = spent, None
    for held in helds:
        for k, split in enumerate(splits()):
            if searches >= budget:
                return None, refusal
            if k not in loose:
                searches += 1
                try:
                    layered(split, (), relaxed=True)
                    loose[k] = True
                except NoFlatLayers as exc:
                    loose[k], refusal = False, refusal or exc
            if not loose[k]:
                continue
            searches += 1
            try:
                return layered(split, held), refusal
            except ValueError as exc:
                refusal = refusal or exc
    return None, refusal


def _stars(part: Part) -> list[tuple[tuple[int, int], ...]]:
    """A plate cut into arms from one shaft joint to each other joint, for each joint."""
    return [tuple(tuple(sorted((s, j))) for j in part.joints if j != s) for s in part.joints]


def _own_trees(part: Part, stars: list, points: np.ndarray) -> list[tuple[tuple[int, int], ...]]:
    """A plate cut into arms along its own links, each a tree of them over its joints: those
    but `stars` among the first MAX_LINK_SETS sets of links, the shortest first (`points`: the
    joints in the assembly pose)."""
    own = []
    for edges in islice(combinations(part.links, len(part.joints) - 1), MAX_LINK_SETS):
        root = {j: j for j in part.joints}
        for u, v in edges:
            while root[u] != u:
                u = root[u]
            while root[v] != v:
                v = root[v]
            if u == v:
                break
            root[u] = v
        else:
            if edges not in stars:
                own.append(edges)
    length = [sum(np.linalg.norm(points[u] - points[v]) for u, v in tree) for tree in own]
    return [own[k] for k in np.argsort(length, kind="stable")]


def _splits(trees: dict[int, list[tuple]]) -> Iterator[dict[int, tuple]]:
    """Every choice of split plates (`trees`: each plate's ways to cut it) in the order of the
    product of [None, *ways] over the plates, the fewest split plates first, but where two
    plates would be fixed on one pin (they would turn as one)."""
    plates = list(trees)
    for count in range(len(plates) + 1):
        chosen = combinations(range(len(plates)), count)
        for picked in sorted(chosen, key=lambda c: [k in c for k in range(len(plates))]):
            for ways in product(*(trees[plates[k]] for k in picked)):
                fixed = [keyed(way) for way in ways]
                if sum(map(len, fixed)) == len(set().union(*fixed)):
                    yield {plates[k]: way for k, way in zip(picked, ways)}


def _candidates(
    assembly: Assembly, paths: np.ndarray, sizes: Sizes, ground: tuple[int, ...]
) -> tuple[Assembly, np.ndarray, list[tuple], np.ndarray]:
    """Every candidate part as the layer search sees it: the real parts, an arm between each
    two joints of every plate (a link), and a bracket for each ground pin and direction (a
    static link from the pivot to its post, a point appended to the paths). The pins are those
    of the real assembly with every candidate at their joint for members, then a shaft at each
    plate joint no pin is at (it lapses unless two arms of the plate meet there), then each
    post, a pin of the ground. Returns it, the extended paths, each candidate's role
    (("part", q), ("arm", q, (joint, joint)) or ("bracket", joint, post)) and the posts
    (B, 2)."""
    parts, roles = list(assembly.parts), [("part", q) for q in range(len(assembly.parts))]
    for q, part in enumerate(assembly.parts):
        for u, v in combinations(part.joints, 2) if part.kind == "plate" else ():
            parts.append(Part(f"{part.name}_arm{u}_{v}", "link", (u, v)))
            roles.append(("arm", q, (u, v)))
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
    for q, part in enumerate(assembly.parts):  # a shaft where no pin is: a split part's own
        for j in (j for j in part.joints if j not in pinned) if q else ():
            members = tuple(k for k, other in enumerate(parts) if j in other.joints)
            pins.append(Pin(f"shaft_{j}", j, q, members))
    brackets = [q for q, role in enumerate(roles) if role[0] == "bracket"]
    pins += [Pin(f"post{k}", first + k, 0, (0, q)) for k, q in enumerate(brackets)]
    still = np.repeat(posts[:, None], paths.shape[1], 1)
    return Assembly(parts, [], pins, []), np.concatenate([paths, still]), roles, posts


SWEPT_KEPT = 4  # candidate sweeps kept: one per width `linkd.export` tries, and to spare
_swept: list[tuple] = []  # (assembly, paths, sizes, what they gave), the latest last


def swept_candidates(
    assembly: Assembly, paths: np.ndarray, sizes: Sizes
) -> tuple[Assembly, list[tuple], np.ndarray, Conflicts]:
    """The candidates (`_candidates`: their assembly, roles and posts) and their conflicts,
    kept for the same assembly, paths and sizes (the very objects): sweeping them takes
    seconds, and `forked` searches the same candidates at each width after this module."""
    for kept in _swept:
        if kept[0] is assembly and kept[1] is paths and kept[2] == sizes:
            return kept[3]
    ground = tuple(pin.joint for pin in assembly.pins if 0 in pin.members)
    union, extended, roles, posts = _candidates(assembly, paths, sizes, ground)
    found = (union, roles, posts, find_conflicts(union, extended, sizes))
    _swept[:] = [*_swept[1 - SWEPT_KEPT :], (assembly, paths, sizes, found)]
    return found


def best_brackets(conflicts: Conflicts, roles: list[tuple]) -> dict[int, int]:
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
    shafts = tuple(Shaft(roles[pin.hub][1], pin.joint, span)  # the hub: an arm of the part
                   for pin, span in zip(chosen.pins, layout.pin_spans)
                   if pin.name.startswith("shaft_"))  # fmt: skip
    top = tuple(j for j in layout.top_joints if j < first)
    return Layout(layers, layout.pin_spans[: len(assembly.pins)], top, layout.count,
                  layout.min_gap, layout.minimal, arms={p: tuple(a) for p, a in arms.items()},
                  brackets=tuple(brackets), shafts=shafts,
                  cover_stubs={k: span for k, span in layout.cover_stubs.items()
                               if k < len(assembly.pins)})  # fmt: skip
