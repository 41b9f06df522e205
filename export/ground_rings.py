"""Parts at other ground pivots on rings, each ring held by a lug on a post beside it: for a
few mechanisms whose ground pins no pin, stub or bracket can hold.

There, every part at some ground pivot sweeps over pins that lie on both sides of it in every
order, so a pin at the pivot would cross a part on a layer between. As the crank does on a
turntable (`turntable`), each part turning about such a pivot is made a disc round it (a ring,
where its nearest joint leaves room for a hole), on a layer of its own, turning in the bore of
a ground ring with no pin at the pivot. A turntable's ring is held by three posts beyond the
sweep, so its bars cross every part on its layer; here the ring has one short lug instead, a
bar out to a post just outside the largest ring at the pivot, standing in the base (or hanging
from the cover) through the layers between, like a ground pin's stub: the layer search keeps
the parts that pass the post off its span, as it does for any pin. On a ring's layer, a part
may still lie where it stays clear of the ring and its lug, and a pin may cross it outside the
ring and clear of the lug's bar, or inside the ring's hole. The lug is tried in LUGS
directions round each pivot.

Pivots are ringed one at a time, then two at once; the other plates may be cut into stars
(`braced`), and the other ground pins held by the base, the cover or both (stubs). The motor's
shaft stays whole, or, where no split layers so, is cut in two on the splits that cut the crank
at the motor, its halves then driven from a layshaft (`drive`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from functools import cached_property, partial
from itertools import combinations, islice, product

import numpy as np

from . import braced
from .layers import Conflicts, Layout, NoFlatLayers, Turntable, largest_step, outlines, stack_layers
from .options import Sizes
from .parts import Assembly, Pin
from .planar import cross, least_distances, point_segment, segment_distance
from .turntable import _hole, _inside, _off_pivot

LUGS = 16  # directions tried for a ring's lug
MAX_RINGED = 2  # ground pivots ringed at once
MAX_SPLITS = 400  # splits of the other plates tried per choice of pivots


@dataclass(frozen=True)
class _Lugs:
    """Where a ring's lug may go, in each of LUGS directions round its pivot, and what comes
    near it (per candidate part; per joint or still post for the pins' paths)."""

    points: np.ndarray  # (LUGS, 2) the posts
    near: np.ndarray  # (LUGS, P) candidates too near a lug to share its layer
    blocked: np.ndarray  # (LUGS, P) candidates passing over its post
    bars: dict[int, np.ndarray]  # (LUGS,) where each lug's bar leaves a part's ring (complex)
    crossed: dict[int, np.ndarray]  # (LUGS, S) joints and posts whose pins cross that bar
    post_reach: float  # how near a still post may come to a bar


@dataclass(frozen=True)
class _Ring:
    """The parts at one ground pivot on rings: their discs, and what comes near the rings; its
    lugs are reckoned only where some split layers with the rings alone (the costly part)."""

    pivot: int
    parts: tuple[int, ...]
    radius: dict[int, float]  # a part's disc
    hole: dict[int, float]  # its hole (0: none)
    inside: dict[int, set[int]]  # the joints whose pins stay inside its hole
    near: dict[int, np.ndarray]  # (P,) candidates that may not share a part's ring's layer
    passing: dict[int, np.ndarray]  # (N,) joints whose pins may not cross it
    outer: dict[int, float]  # each part's ground ring's rim
    union: Assembly
    still: np.ndarray  # (S, T, 2) the joints' paths, then the still posts
    sizes: Sizes
    step: float  # the sweep's largest

    def turntables(self, layers: np.ndarray, lug: int, spans: list) -> list[Turntable]:
        """Each part's ring at its layer, its ground ring held by the lug's post(s) over `spans`."""
        post = (tuple(map(float, self.lugs.points[lug])),) * len(spans)
        return [Turntable(p, self.pivot, int(layers[p]), self.radius[p],
                          self.radius[p] + self.sizes.clearance, post, self.hole[p], tuple(spans))
                for p in self.parts]  # fmt: skip

    @cached_property
    def lugs(self) -> _Lugs:
        """Each lug half a width outside every ring at the pivot, its bar from each ring's rim."""
        width, clearance = self.sizes.link_width, self.sizes.clearance
        reach = self.sizes.hole_diameter / 2 + clearance + self.step
        centre = complex(*self.still[self.pivot, 0])
        circle = np.exp(2j * np.pi * np.arange(LUGS) / LUGS)
        out = max(self.outer.values()) + width / 2
        lugs = centre + out * circle
        rim = centre + (min(self.outer.values()) - width / 2) * circle
        points = self.still[..., 0] + 1j * self.still[..., 1]  # (S, T)
        bars = {p: centre + self.outer[p] * circle for p in self.parts}
        near, passing = width + clearance + self.step, width / 2 + reach
        return _Lugs(
            np.stack([lugs.real, lugs.imag], -1),
            _distances(self.union, self.still, rim, lugs, near) < near,
            _distances(self.union, self.still, lugs, lugs, passing) < passing,
            bars,
            {p: _crossing(points, centre, self.outer[p], out, circle, passing) for p in bars},
            width / 2 + self.sizes.hole_diameter / 2 + clearance,
        )


def ground_rings_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with the parts at one or two ground pivots on rings held by lugs (NoFlatLayers
    where none of those choices layers)."""
    union, roles, posts, conflicts = braced.swept_candidates(assembly, paths, sizes)
    motor = assembly.crank.joint
    pivots = [pin.joint for pin in assembly.pins if 0 in pin.members and pin.joint != motor]
    rings: dict[int, _Ring] = {}
    loose = _loosest(union, conflicts, roles, sizes, motor, tuple(pivots))
    for count in range(1, MAX_RINGED + 1):
        for ringed in combinations(pivots, count):
            taken = {m for pin in assembly.pins if pin.joint in ringed for m in pin.members if m}
            splits = [(cut, s) for cut, s in _tried(assembly, paths, taken) if loose(s)]
            if not splits:  # the rings' sizes and distances are the costly part: not needed
                continue
            for g in ringed:
                if g not in rings:
                    rings[g] = _ring(assembly, union, posts, paths, sizes, g)
            found = _search(assembly, paths, sizes, union, roles, posts, conflicts,
                            [rings[g] for g in ringed], splits)  # fmt: skip
            if found is not None:
                return found
    raise NoFlatLayers("no ground pivots on rings layer")


def _tried(assembly: Assembly, paths: np.ndarray, taken: set[int]) -> Iterator[tuple[bool, dict]]:
    """The splits of the plates but those `taken` tried, each with whether the motor's shaft is
    cut: up to MAX_SPLITS into stars with it whole, then as many of those into stars and trees
    of their own links that cut the crank at the motor (`drive`), with it cut."""
    plates = [q for q, part in enumerate(assembly.parts) if part.kind == "plate" and q not in taken]
    stars, ways = braced._cuts(assembly, plates, paths)
    crank, motor = assembly.crank.child, assembly.crank.joint
    yield from ((False, s) for s in islice(braced._splits(stars), MAX_SPLITS))
    halves = (s for s in braced._splits(ways) if sum(motor in a for a in s.get(crank, ())) >= 2)
    yield from ((True, s) for s in islice(halves, MAX_SPLITS))


def _ring(
    assembly: Assembly,
    union: Assembly,
    posts: np.ndarray,
    paths: np.ndarray,
    sizes: Sizes,
    pivot: int,
) -> _Ring:
    """The rings at `pivot`: each part's disc reaches half a width past its farthest joint,
    its ground ring a clearance and half a width more, the lug half a width beyond that."""
    width, clearance, step = sizes.link_width, sizes.clearance, largest_step(paths)
    pin = next(pin for pin in assembly.pins if pin.joint == pivot)
    parts = tuple(m for m in pin.members if m)
    away = np.linalg.norm(paths - paths[pivot, :1], axis=-1)  # (N, T)
    radius, hole, inside = {}, {}, {}
    for p in parts:
        radii = away[[j for j in assembly.parts[p].joints if j != pivot], 0]
        radius[p], hole[p] = radii.max() + width / 2, _hole(radii.min(), sizes)
        inside[p] = _inside(paths, pivot, sizes, hole[p])
    outer = {p: radius[p] + clearance + width / 2 for p in parts}  # each ground ring's rim
    centre = complex(*paths[pivot, 0])
    still = np.concatenate([paths, np.repeat(posts[:, None], paths.shape[1], 1)])
    to_ring = _distances(union, still, np.array([centre]), np.array([centre]))[0]
    reach = sizes.hole_diameter / 2 + clearance + step
    return _Ring(
        pivot, parts, radius, hole, inside,
        near={p: to_ring < outer[p] + width / 2 + clearance + step for p in parts},
        passing={p: away.min(1) < outer[p] + reach for p in parts},
        outer=outer, union=union, still=still, sizes=sizes, step=step,
    )  # fmt: skip


def _distances(
    union: Assembly, paths: np.ndarray, a: np.ndarray, b: np.ndarray, below: float | None = None
) -> np.ndarray:
    """(S, P) the least distance over the sweep between each still segment a-b (complex) and
    each candidate's outline (0 where an end lies inside a plate); with `below`, only whether
    it is below that is exact (`least_distances`)."""
    points, owner, ends = outlines(union, paths)
    start, end = points[ends[:, 0]], points[ends[:, 1]]
    count = paths.shape[1]
    a, b = np.repeat(a[:, None], count, 1), np.repeat(b[:, None], count, 1)
    gap = least_distances(a, b, start, end, segment_distance, below=below)
    out = np.full((len(a), len(union.parts)), np.inf)
    np.minimum.at(out, (np.arange(len(a))[:, None], owner[None, :]), gap)
    for q in range(len(union.parts)):
        mine = owner == q
        if mine.sum() >= 3:  # a plate: an end inside it
            for ends_at in (a, b):
                left = cross(start[mine][None], end[mine][None], ends_at[:, None]) >= 0
                out[left.all(1).any(-1), q] = 0.0
    return out


def _crossing(
    points: np.ndarray,
    centre: complex,
    inner: float,
    outer: float,
    circle: np.ndarray,
    reach: float,
) -> np.ndarray:
    """(L, S) whether each path of `points` (S, T, complex) comes within `reach` of the bar
    from `inner` to `outer` about `centre` in each direction of `circle` (L,): reckoned only at
    the angles where the point lies near that annulus (few)."""
    away = np.abs(points - centre)
    joint, angle = np.nonzero((away > inner - reach) & (away < outer + reach))
    crossed = np.zeros((len(circle), len(points)), bool)
    if len(joint):
        bars = (centre + inner * circle)[:, None], (centre + outer * circle)[:, None]
        hit = point_segment(points[joint, angle], *bars) < reach  # (L, K), by joint
        first = np.flatnonzero(np.r_[True, joint[1:] != joint[:-1]])
        crossed[:, joint[first]] = np.logical_or.reduceat(hit, first, axis=1)
    return crossed


def _search(
    assembly: Assembly,
    paths: np.ndarray,
    sizes: Sizes,
    union: Assembly,
    roles: list[tuple],
    posts: np.ndarray,
    conflicts: Conflicts,
    rings: list[_Ring],
    splits: list[tuple[bool, dict]],
) -> Layout | None:
    """The first of the `splits` of the other plates (with the motor's shaft cut or whole), and
    then lug directions, that layer with `rings` (a split is only given its lugs where it
    layers without them, a looser problem)."""
    for ring in rings:
        arms = {q for q, role in enumerate(roles) if role[0] == "arm" and role[1] in ring.parts}
        union = _off_pivot(union, ring.pivot, set(ring.parts), arms)
    conflicts = _ringed(union, conflicts, rings)
    motor, first = assembly.crank.joint, len(posts) + len(paths)
    for cut, split in splits:
        keep = braced._kept(roles, split, [])
        layered = partial(_layered, roles=roles, keep=keep, sizes=sizes, motor=motor, cut=cut)
        if layered(union, conflicts, fewest=False) is None:
            continue
        directions = [range(LUGS)]  # with several rings, each one's lugs that layer alone
        if len(rings) > 1:
            directions = [[lug for lug in range(LUGS)
                           if layered(*_lugged(union, conflicts, [ring], (lug,), first),
                                      fewest=False) is not None]
                          for ring in rings]  # fmt: skip
        for lugs in product(*directions):
            lugged, with_lugs = _lugged(union, conflicts, rings, lugs, first)
            if layered(lugged, with_lugs, fewest=False) is None:
                continue
            layout, chosen = layered(lugged, with_lugs, fewest=True)
            return _real(assembly, layout, chosen, [roles[q] for q in keep], posts, len(paths),
                         sizes, rings, lugs)  # fmt: skip
    return None


def _loosest(
    union: Assembly,
    conflicts: Conflicts,
    roles: list[tuple],
    sizes: Sizes,
    motor: int,
    pivots: tuple[int, ...],
) -> Callable[[dict], bool]:
    """Whether a split layers with the pins at all the `pivots` left out and the motor's shaft
    free to be cut: looser than rings at any of them, so a split that does not is not tried
    with rings at all (asked once per split, for every choice of pivots)."""
    seen: dict[tuple, bool] = {}

    def layers(split: dict) -> bool:
        key = tuple(sorted(split.items()))
        if key not in seen:
            keep = braced._kept(roles, split, [])
            chosen, share = braced._subset(union, conflicts, keep, (), dropped=pivots)
            shafts = [k for k in braced._shafts(chosen, [roles[q] for q in keep])
                      if chosen.pins[k].joint != motor]  # fmt: skip
            try:
                stack_layers(chosen, share, sizes, stubs=True, whole=shafts, fewest=False)
                seen[key] = True
            except NoFlatLayers:
                seen[key] = False
        return seen[key]

    return layers


def _ringed(union: Assembly, conflicts: Conflicts, rings: list[_Ring]) -> Conflicts:
    """The conflicts with each ring on its part's layer: what comes near the ring may not share
    it, and no pin whose path comes near may cross it but the part's own and those inside its
    hole."""
    near = conflicts.parts.copy()
    blocked = [list(parts) for parts in conflicts.blocked]
    for ring in rings:
        for p in ring.parts:
            row = ring.near[p].copy()
            row[[0, p]] = False
            near[p] |= row
            near[:, p] |= row
            for pin, parts in zip(union.pins, blocked):
                own = p in pin.members or pin.name.startswith("post")
                crossing = pin.joint < len(ring.passing[p]) and ring.passing[p][pin.joint]
                if crossing and not own and pin.joint not in ring.inside[p] and p not in parts:
                    parts.append(p)
    return replace(conflicts, parts=near, blocked=blocked)


def _lugged(
    union: Assembly, conflicts: Conflicts, rings: list[_Ring], lugs: tuple[int, ...], first: int
) -> tuple[Assembly, Conflicts]:
    """The rings given their lugs (one direction each): the lug's post a ground pin at joint
    `first + k` through the rings of its pivot, what comes near the lug off their layers, and
    every pin that would cross a lug's bar (another ring's post too) off its ring's layer."""
    pins, near = list(union.pins), conflicts.parts.copy()
    blocked = [list(parts) for parts in conflicts.blocked]
    for k, (ring, lug) in enumerate(zip(rings, lugs)):
        pins.append(Pin(f"lug{k}", first + k, 0, (0, *ring.parts)))
        passing = ring.lugs.blocked[lug].copy()
        passing[[0, *ring.parts]] = False
        blocked.append(np.flatnonzero(passing).tolist())
        for p in ring.parts:
            row = ring.lugs.near[lug].copy()
            row[[0, p]] = False
            near[p] |= row
            near[:, p] |= row
    for ring, lug in zip(rings, lugs):
        for p in ring.parts:
            a, b = ring.lugs.bars[p][lug], complex(*ring.lugs.points[lug])
            for pin, parts in zip(pins, blocked):
                if p in pin.members or p in parts:
                    continue
                if pin.joint < first:
                    crossing = ring.lugs.crossed[p][lug, pin.joint]
                else:  # another ring's lug post
                    other, at = rings[pin.joint - first], lugs[pin.joint - first]
                    post = complex(*other.lugs.points[at])
                    crossing = point_segment(post, a, b) < other.lugs.post_reach
                if crossing:
                    parts.append(p)
    return replace(union, pins=pins), replace(conflicts, parts=near, blocked=blocked)


def _layered(
    union: Assembly,
    conflicts: Conflicts,
    roles: list[tuple],
    keep: list[int],
    sizes: Sizes,
    motor: int,
    cut: bool,
    fewest: bool,
) -> tuple[Layout, Assembly] | None:
    """The layers of the candidates `keep` with the ground pins as stubs, but a split part's
    shafts and, unless `cut`, the motor's, which stay whole (None where none layers)."""
    chosen, share = braced._subset(union, conflicts, keep, ())
    shafts = braced._shafts(chosen, [roles[q] for q in keep])
    if cut:
        shafts = [k for k in shafts if chosen.pins[k].joint != motor]
    else:
        shafts += [k for k, pin in enumerate(chosen.pins) if pin.joint == motor]
    try:
        return stack_layers(chosen, share, sizes, stubs=True, whole=shafts, fewest=fewest), chosen
    except NoFlatLayers:
        return None


def _real(
    assembly: Assembly,
    layout: Layout,
    chosen: Assembly,
    kept: list[tuple],
    posts: np.ndarray,
    first: int,
    sizes: Sizes,
    rings: list[_Ring],
    lugs: tuple[int, ...],
) -> Layout:
    """The real parts' layout (`braced._real`, the pins put back in the assembly's order, a
    ringed pivot's pin, left to the ground alone, at no layer), with the rings' turntables:
    each lug's post spans the pin the search gave it (two posts where it was cut into stubs)."""
    at = {pin.name: k for k, pin in enumerate(chosen.pins)}
    order = [at.get(pin.name) for pin in assembly.pins]
    order += [k for k, pin in enumerate(chosen.pins) if k not in order]
    spans = [layout.pin_spans[k] if k is not None else (0, 0) for k in order]
    placed = [chosen.pins[k] if k is not None else pin
              for k, pin in zip(order, [*assembly.pins, *chosen.pins])]  # fmt: skip
    index = {k: n for n, k in enumerate(order) if k is not None}
    stubs = {index[k]: span for k, span in layout.cover_stubs.items()}
    aligned = replace(layout, pin_spans=spans, cover_stubs=stubs)
    real = braced._real(assembly, aligned, replace(chosen, pins=placed), kept, posts, first)
    tables = []
    for k, (ring, lug) in enumerate(zip(rings, lugs)):
        pin = at[f"lug{k}"]
        held = [layout.pin_spans[pin]] + ([layout.cover_stubs[pin]] if pin in layout.cover_stubs
                                          else [])  # fmt: skip
        tables += ring.turntables(real.layers, lug, held)
    return replace(real, turntables=tuple(tables))
