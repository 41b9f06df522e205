"""Give every part a z-layer so that parts sharing a layer never come near each other.

The analytic kinematics sweeps a full crank revolution. A part's outline is the convex hull of
its joints grown by half the link width, so two parts may share a layer only if their hulls stay
a width plus the clearance apart at every angle. A pin crosses every layer between the outermost
parts it joins, so a part that comes near a pin may not sit on those layers. The conflict graph
is coloured with as few layers as can keep every pin clear (`stacking`).

The ground is a base plate under the stack of moving parts: the pins of ground joints stand in
it. When no order of the stack lets every such pin reach up clear of the others, some pins hang
from a cover plate over the stack instead (the two plates are one rigid frame). Where even
that fails (`braced` asks), each part at a ground joint may be held from either plate: the
joint's pin is then two coaxial stubs, one standing in the base through the parts below those
passing over the joint, one hanging from the cover through the parts above them.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field
from itertools import combinations, pairwise
from typing import TYPE_CHECKING, NoReturn

import numpy as np

from linkd.mechanism import Mechanism

from .options import Sizes
from .parts import Assembly, joint_paths
from .planar import convex_hull, cross, least_distances, to_segment
from .stacking import PinState, fewest_layers, find_order, stack_in_order

if TYPE_CHECKING:
    from .drive import Drive

SWEEP_ANGLES = 720  # crank angles of a first sweep
MAX_SWEEP_ANGLES = 8192
SWEEP_STEP = 0.05  # of the link width: the most a joint may move between two sampled angles
MAX_COVER_TRIES = 4  # choices of ground pins hanging from a cover plate, per layer count


@dataclass(frozen=True)
class Arm:
    """One plate of a part split into arms: a bar between two of the part's joints."""

    joints: tuple[int, int]
    layer: int


class NoFlatLayers(ValueError):
    """No order of flat layers keeps every pin clear (proved)."""


@dataclass(frozen=True)
class Shaft:
    """The pin a split part's arms are fixed on, at a joint the part shares with no other part
    (elsewhere the joint's own pin is the shaft). It is named as a pin would be there."""

    part: int
    joint: int
    span: tuple[int, int]  # (lowest, highest) layer: the part's arms

    @property
    def name(self) -> str:
        return f"pin_{self.joint}"


@dataclass(frozen=True)
class Fork:
    """A pin cut into coaxial rods where `part` is forked (`forked`): each rod is fixed in the
    part's arms it passes, and other parts (the ground: 0) turn on it."""

    part: int
    rods: tuple[tuple[tuple[int, ...], tuple[int, int]], ...]  # (the parts turning on it, its
    # layer span), bottom up
    hubs: tuple[int, ...] = ()  # the part each rod is fixed in, where not all in `part` (a
    # crank cut in two: a rod in each half, `drive`)


@dataclass(frozen=True)
class Bracket:
    """A ground plate on a layer inside the stack, holding the pin of a ground joint, with an
    arm out to a post that stands in the base plate (or hangs from the cover)."""

    joint: int
    post: tuple[float, float]  # the post's axis, mechanism units (assembly frame)
    layer: int
    top: bool  # the post hangs from the cover rather than standing in the base


@dataclass(frozen=True)
class Strap:
    """An eccentric strap (`strapped`): part `part` turns about `joint` on a sheave, a disc of
    `radius` fixed in part `sheave_of` on the strap's layer, and the pins of `passing` (indices
    of pins at the sheave's part's other joints) pass through the sheave, clear of the strap."""

    part: int
    joint: int
    sheave_of: int
    radius: float  # mechanism units
    passing: tuple[int, ...]
    arm: tuple[int, int] | tuple[()] = ()  # the arm's joints where the strap is an arm of a split
    # part (`braced.split_straps_layers`)


@dataclass(frozen=True)
class Turntable:
    """A part at the motor's pivot `joint` made a disc of `radius` round it (`turntable`), or a
    ring where it has a `hole`, with no pin there: it turns in the bore of a ground ring on its
    layer, held by `posts` from the base; or the same at another ground pivot, its ring held
    by a lug on a post (`ground_rings`) that spans the layers `spans` gives."""

    part: int
    joint: int
    layer: int
    radius: float  # mechanism units, as the bore's and the hole's
    bore: float
    posts: tuple[tuple[float, float], ...]
    hole: float = 0.0  # a ring's: the radius of its hole, which pins may pass
    spans: tuple[tuple[int, int], ...] = ()  # each post's (lowest, highest) layer, where given


@dataclass(frozen=True)
class Layout:
    layers: np.ndarray  # (P,) layer of every part; the ground's (base plate) is 0
    pin_spans: list[tuple[int, int]]  # (lowest, highest) layer of each pin, plates included
    top_joints: tuple[int, ...]  # ground joints held by a cover plate on the top layer
    count: int  # number of layers, base and cover plates included
    min_gap: float  # least in-plane gap between the outlines of parts on one layer (inf if none)
    minimal: bool = True  # fewer layers cannot work (proved; False where not searched)
    bends: dict[int, np.ndarray] = field(default_factory=dict)  # bent links' waypoints (routing)
    arms: dict[int, tuple[Arm, ...]] = field(default_factory=dict)  # split parts (`braced`)
    brackets: tuple[Bracket, ...] = ()  # ground pins held between the layers (`braced`)
    shafts: tuple[Shaft, ...] = ()  # split parts' own pins at joints no other part shares
    cover_stubs: dict[int, tuple[int, int]] = field(default_factory=dict)  # see `rods.pin_rods`
    forks: dict[int, Fork] = field(default_factory=dict)  # pins cut into rods, by pin index
    straps: tuple[Strap, ...] = ()  # parts that turn on sheaves (`strapped`)
    frames: tuple[int, ...] = ()  # layers of ground plates between modules (`framed`)
    frame_posts: tuple[tuple[float, float], ...] = ()  # posts holding them, base to cover
    turntables: tuple[Turntable, ...] = ()  # parts at the motor's pivot on turntables
    drive: Drive | None = None  # the crank cut in two, its halves driven from a layshaft


@dataclass(frozen=True)
class Conflicts:
    parts: np.ndarray  # (P, P) bool: the two parts may not share a layer
    blocked: list[list[int]]  # per pin: parts that come near it (they may not sit within its span)
    distance: np.ndarray  # (P, P) least distance between the parts' joint hulls over the sweep


def hull_edges(
    assembly: Assembly, positions: np.ndarray, chains: dict[int, list[int]] | None = None
) -> list[tuple[int, int, int]]:
    """(part, point, next point) along each part's hull in the assembly pose, counter-clockwise,
    or along its chain of bars (a bent link: `chains` maps it to its points, in order).

    A two-joint hull is one segment, a one-joint hull a point (a segment of zero length).
    """
    chains = chains or {}
    edges = []
    for p, part in enumerate(assembly.parts):
        if p in chains:
            edges += [(p, a, b) for a, b in pairwise(chains[p])]
            continue
        joints = list(part.joints)
        hull = [joints[k] for k in convex_hull(positions[joints])]
        if len(hull) <= 2:
            edges.append((p, hull[0], hull[-1]))
        else:
            edges += [(p, a, b) for a, b in zip(hull, hull[1:] + hull[:1])]
    return edges


def sweep(mech: Mechanism, width: float) -> np.ndarray:
    """(N, T, 2) joint paths over a revolution, sampled so finely that no joint moves more than
    SWEEP_STEP link widths between two angles (within MAX_SWEEP_ANGLES)."""
    paths = joint_paths(mech, np.arange(SWEEP_ANGLES) * (2 * np.pi / SWEEP_ANGLES))
    step = largest_step(paths)
    count = min(MAX_SWEEP_ANGLES, int(np.ceil(SWEEP_ANGLES * step / (SWEEP_STEP * width))))
    if count <= SWEEP_ANGLES:
        return paths
    return joint_paths(mech, np.arange(count) * (2 * np.pi / count))


def largest_step(paths: np.ndarray) -> float:
    """The furthest any of the (N, T, 2) points moves between two sampled angles (cyclic)."""
    return float(np.linalg.norm(np.diff(paths, axis=1, append=paths[:, :1]), axis=-1).max())


def outlines(
    assembly: Assembly, paths: np.ndarray, chains: dict[int, list[int]] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (N, T) points of the sweep as complex numbers, and each outline segment's part (E,)
    and its two ends among them (E, 2): the hull edges of `hull_edges`."""
    edges = hull_edges(assembly, paths[:, 0], chains)
    points = paths[..., 0] + 1j * paths[..., 1]
    return points, np.array([e[0] for e in edges]), np.array([e[1:] for e in edges])


def _fixed_apart(points: np.ndarray) -> np.ndarray:
    """(N, N) bool: the pairs of the (N, T) points that keep their distance over the sweep (on
    one part or both on the ground): four points that keep all theirs move as one body."""
    tolerance = 1e-9 * np.abs(points).max() ** 2
    x, y = points.real, points.imag

    def spread(i: np.ndarray, j: np.ndarray, angles: slice) -> np.ndarray:
        return np.ptp((x[i, angles] - x[j, angles]) ** 2 + (y[i, angles] - y[j, angles]) ** 2, -1)

    i, j = np.triu_indices(len(points), 1)
    still = (np.ptp(x, -1) == 0) & (np.ptp(y, -1) == 0)  # the ground's: most of a bracket's points
    fixed = np.eye(len(points), dtype=bool)
    both = still[i] & still[j]
    fixed[i[both], j[both]] = True
    i, j = i[~both], j[~both]
    for angles in (slice(None, None, 16), slice(None)):  # at every 16th angle first
        kept = spread(i, j, angles) <= tolerance
        i, j = i[kept], j[kept]
    fixed[i, j] = True
    return fixed | fixed.T


def find_conflicts(
    assembly: Assembly, paths: np.ndarray, sizes: Sizes, chains: dict[int, list[int]] | None = None
) -> Conflicts:
    """Moving part pairs that may not share a layer, and the parts each pin's span must avoid.

    paths: (N, T, 2) joint positions over the sweep, then the waypoints of bent links, whose
    outlines are the open `chains` of points. Distances are between joint hulls (or chains),
    which the plates cover with half a width to spare; the largest point step between two
    sampled angles is added to each margin, so what happens between samples is covered too.
    """
    chains = chains or {}
    n_parts, n_joints = len(assembly.parts), len(paths)
    points, owner, ends = outlines(assembly, paths, chains)
    start, end = points[ends[:, 0]], points[ends[:, 1]]  # (E, T)
    fixed = _fixed_apart(points)
    joined = fixed[ends[:, 0], ends[:, 1]]  # the edges that keep their length
    both = fixed[ends[:, None, :, None], ends[None, :, None]].all((2, 3))  # (E, E): 4 ends
    rigid = joined[:, None] & joined & both
    edge_gap = least_distances(start, end, start, end, symmetric=True, rigid=rigid)
    rigid = joined & fixed[:, ends[:, 0]] & fixed[:, ends[:, 1]]  # joints that ride with an edge
    joint_gap = least_distances(points, points, start, end, to_segment, rigid=rigid)
    distance = np.full((n_parts, n_parts), np.inf)
    np.minimum.at(distance, (owner[:, None], owner[None, :]), edge_gap)
    to_part = np.full((n_joints, n_parts), np.inf)
    np.minimum.at(to_part, (np.arange(n_joints)[:, None], owner[None, :]), joint_gap)
    for q in range(n_parts):
        mine = owner == q
        if mine.sum() >= 3 and q not in chains:  # a polygon: a joint inside it is at distance 0
            left = cross(start[mine][None], end[mine][None], points[:, None]) >= 0  # (N, e, T)
            to_part[left.all(1).any(-1), q] = 0.0
    for p, part in enumerate(assembly.parts):
        inside = to_part[chains.get(p, list(part.joints))].min(0)  # a vertex of p inside q
        distance[p] = np.minimum(distance[p], inside)
        distance[:, p] = np.minimum(distance[:, p], inside)
    step = largest_step(paths)
    width, clearance = sizes.link_width, sizes.clearance
    near = distance < width + clearance + step
    np.fill_diagonal(near, False)
    near[0], near[:, 0] = False, False  # the ground's plates have layers of their own
    pin_reach = (width + sizes.hole_diameter) / 2 + clearance + step
    blocked = [
        [q for q in range(1, n_parts) if q not in pin.members and to_part[pin.joint, q] < pin_reach]
        for pin in assembly.pins
    ]
    return Conflicts(near, blocked, distance)


def assign_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """The layer of every part, with as few layers as can be.

    Layer 0 is the ground's base plate, under the stack of moving parts (layers 1..K). Each
    ground joint's pin stands in the base and reaches up to its highest part; where no order
    of the parts allows that, some pins hang from a cover plate over the stack instead (layer
    K + 1). First an order of the parts that keeps every pin clear is found (or the mechanism
    cannot be built flat: ValueError), then the fewest layers.
    """
    return stack_layers(assembly, find_conflicts(assembly, paths, sizes), sizes)


def stack_layers(
    assembly: Assembly,
    conflicts: Conflicts,
    sizes: Sizes,
    stubs: bool = False,
    whole: Collection[int] = (),
    fewest: bool = True,
) -> Layout:
    """The layers of `assign_layers` for given conflicts (ValueError as there). stubs: the
    parts of each ground pin but those `whole` (a split part's shaft) may be held from either
    plate (`braced`), which is looser than any cover choice. It is searched first (where it
    cannot work, nothing else can); then every pin in the base, and failing that the stubs'
    order is taken. fewest: search for the fewest layers; without it, the first order's
    layers (a check whether any layering exists, as the bounds of the costlier constructions
    ask, skips that search)."""
    moving = conflicts.parts[1:, 1:]
    pins = [
        ([m - 1 for m in pin.members if m], [b - 1 for b in blocked])
        for pin, blocked in zip(assembly.pins, conflicts.blocked)
    ]
    grounded = {k for k, pin in enumerate(assembly.pins) if 0 in pin.members}
    covers = [set(c) for r in range(len(grounded) + 1) for c in combinations(sorted(grounded), r)]
    covers = covers[: 1 + MAX_COVER_TRIES]  # no cover first, then the smallest
    loose = None  # the stubs' order and pins
    if stubs and grounded:  # stubs can do what a cover does: besides them only the base is tried
        state = _pin_state(len(moving), pins, grounded, None, whole)
        loose = find_order(state, moving), state
        if loose[0] is None:
            _refuse()
        covers = covers[:1]
    for cover in covers:
        state = _pin_state(len(moving), pins, grounded, cover, whole)
        order = find_order(state, moving)
        if order is not None:
            break
    else:
        if loose is None:
            _refuse()
        (order, state), cover = loose, None
    layers = stack_in_order(moving, order)
    if fewest:
        layers = fewest_layers(moving, state, layers)
    return _layout(assembly, conflicts, sizes, layers, cover, max(layers), fewest)


def _refuse() -> NoReturn:
    raise NoFlatLayers(
        "cannot be built from flat layers: some parts pass over pins whose plates lie above and "
        "below them, in every order"
    )


def _pin_state(
    n: int, pins: list, grounded: set[int], cover: set[int] | None, whole: Collection[int]
) -> PinState:
    """The pins' state for a search of n parts: ground pins stand in the base but those of
    `cover`, which hang from the cover. With cover None, each part at a ground joint is held
    from the plate on its side of the parts passing over the joint: that is a pin whose plates
    are the passing parts and whose blocked parts are the joint's (none may lie between two
    passing parts). A pin that must stay `whole` also keeps the passing parts from between its
    own plates, so they all lie on one side: base or cover, whichever the search reaches."""
    if cover is None:
        swapped = []
        for k, (members, passing) in enumerate(pins):
            if k in grounded:
                swapped.append((passing, members))
            if k not in grounded or k in whole:
                swapped.append((members, passing))
        return PinState(n, swapped, set(), set())
    return PinState(n, pins, grounded, cover)


def _layout(assembly, conflicts, sizes, moving_layers, cover, stack, minimal) -> Layout:
    """The layout of a search result: layers 1..stack of the moving parts, base and cover (a
    ground pin's parts held from the cover: all of `cover`'s, or with cover None those above
    the parts passing over the joint)."""
    layers = np.array([0, *moving_layers])
    top_layer = stack + 1
    spans, top, stubs = [], [], {}
    for k, pin in enumerate(assembly.pins):
        mine = sorted(int(layers[m]) for m in pin.members if m)
        if not mine:  # a ground pin nothing turns on (the motor's, under a turntable)
            spans.append((0, 0))
            continue
        if 0 not in pin.members:
            spans.append((mine[0], mine[-1]))
            continue
        passing = [int(layers[b]) for b in conflicts.blocked[k]]
        if cover is None:
            high = [layer for layer in mine if passing and layer > min(passing)]
        else:
            high = mine if k in cover else []
        low = [layer for layer in mine if layer not in high]
        if not low:
            top.append(pin.joint)
            spans.append((high[0], top_layer))
            continue
        spans.append((0, low[-1]))
        if high:
            stubs[k] = (high[0], top_layer)
    count = stack + 1 + bool(top or stubs)
    return Layout(layers, spans, tuple(sorted(top)), count, least_gap(conflicts, layers, sizes),
                  minimal, cover_stubs=stubs)  # fmt: skip


def least_gap(conflicts: Conflicts, layers: np.ndarray, sizes: Sizes) -> float:
    """The least in-plane gap between the outlines of two parts on one layer (inf if none);
    what is on layer 0 (the ground, or a candidate left out) is not counted."""
    same = (layers[:, None] == layers[None, :]) & ~np.eye(len(layers), dtype=bool)
    same &= (layers[:, None] > 0) & (layers[None, :] > 0)
    return float((conflicts.distance[same] - sizes.link_width).min(initial=np.inf))
