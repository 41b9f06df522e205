"""Bent links: a binary link that takes a detour around the pins it would pass over.

A pin spans every layer between the outermost parts it joins, so a part that comes near it may
not sit on those layers. Seen from a link, a pin traces a closed relative path over the
revolution; unless that path (grown by the pin's reach) separates the link's two joints, the
link can go around it: a chain of straight bars through a few waypoints that are rigid on the
link, as builders make cranked links. Routes are shortest paths on a grid in the link's
assembly-pose frame, pulled straight between the waypoints, with the reach kept as clearance.
Where a pin's path runs over one of the link's joints or circles one and not the other, no
route exists; when the pins left after those cannot be layered either, bending is not tried.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse.csgraph import dijkstra

from .layers import Layout, find_conflicts, largest_step, stack_layers
from .options import Sizes
from .parts import Assembly, part_rotations
from .planar import segment_distance

GRID_CELLS = 240  # cells along the longer side of a routing grid
MAX_WAYPOINTS = 6  # bends of a route; a longer one is not worth building
ROUNDS = 3  # routings, each around the pins that still block the links routed before
NEIGHBOURS = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]


def relative_path(paths: np.ndarray, turns: np.ndarray, joints: tuple, point: int) -> np.ndarray:
    """(T, 2) path of mechanism joint `point` in a part's frame, given as assembly-pose
    coordinates (the part's first joint `a` stays at its assembly position)."""
    a = joints[0]
    d = (paths[point, :, 0] - paths[a, :, 0]) + 1j * (paths[point, :, 1] - paths[a, :, 1])
    local = d * np.exp(-1j * turns) + (paths[a, 0, 0] + 1j * paths[a, 0, 1])
    return np.stack([local.real, local.imag], -1)


def rigid_paths(paths: np.ndarray, turns: np.ndarray, joint: int, points: np.ndarray) -> np.ndarray:
    """(K, T, 2) world paths of points (K, 2) fixed on a part that turns by `turns` (T,) from
    the assembly pose about its joint `joint`."""
    anchor = paths[joint, :, 0] + 1j * paths[joint, :, 1]  # (T,)
    offset = (points[:, 0] - paths[joint, 0, 0]) + 1j * (points[:, 1] - paths[joint, 0, 1])
    world = anchor[None] + offset[:, None] * np.exp(1j * turns)[None]
    return np.stack([world.real, world.imag], -1)


def _segments(obstacles: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Start and end points (complex) of the segments of closed obstacle paths."""
    rings = [np.concatenate([o, o[:1]]) for o in obstacles]
    ends = [(r[:-1, 0] + 1j * r[:-1, 1], r[1:, 0] + 1j * r[1:, 1]) for r in rings]
    return np.concatenate([e[0] for e in ends]), np.concatenate([e[1] for e in ends])


def clearance(chain: np.ndarray, segments: tuple[np.ndarray, np.ndarray]) -> float:
    """Least distance between an open chain of points (k, 2) and obstacle segments."""
    a = chain[:, 0] + 1j * chain[:, 1]
    return float(min(segment_distance(a[k], a[k + 1], *segments).min() for k in range(len(a) - 1)))


def route(ends: np.ndarray, obstacles: list[np.ndarray], reach: float) -> np.ndarray | None:
    """Waypoints (k, 2) of a chain from ends[0] to ends[1] that keeps `reach` from every
    obstacle path, ends excluded (k = 0: the straight link is clear); None if there is none.

    Free cells keep reach plus two cells from the rasterised paths, so a straight bar through
    free cells (sampled every half cell) keeps the reach from the paths themselves."""
    if clearance(ends, _segments(obstacles)) >= reach:
        return np.empty((0, 2))
    points = np.concatenate([ends, *obstacles])
    lo = points.min(0) - 3 * reach
    cell = float((points.max(0) + 3 * reach - lo).max()) / GRID_CELLS
    shape = tuple(np.ceil((points.max(0) + 3 * reach - lo) / cell).astype(int) + 1)
    free = ndimage.distance_transform_edt(~_raster(obstacles, lo, cell, shape)) * cell
    grid = _Grid(free > reach + 2 * cell, lo, cell)
    start, goal = grid.cell(ends[0]), grid.cell(ends[1])
    if not (grid.free[start] and grid.free[goal]):
        return None
    cells = _shortest(grid.free, start, goal)
    if cells is None:
        return None
    chain = np.concatenate([ends[:1], lo + cells[1:-1] * cell, ends[1:]])
    waypoints = _pull(chain, grid)
    return waypoints if len(waypoints) <= MAX_WAYPOINTS else None


class _Grid:
    """Free cells of a routing grid, and whether a straight bar stays on them."""

    def __init__(self, free: np.ndarray, lo: np.ndarray, cell: float):
        self.free, self.lo, self.size = free, lo, cell

    def cell(self, point: np.ndarray) -> tuple:
        return tuple(np.round((point - self.lo) / self.size).astype(int))

    def clear(self, a: np.ndarray, b: np.ndarray) -> bool:
        steps = int(np.ceil(np.linalg.norm(b - a) / (self.size / 2))) + 1
        t = np.linspace(0.0, 1.0, steps)[:, None]
        index = np.round((a + (b - a) * t - self.lo) / self.size).astype(int)
        return bool(self.free[index[:, 0], index[:, 1]].all())


def _raster(obstacles: list[np.ndarray], lo: np.ndarray, cell: float, shape: tuple) -> np.ndarray:
    """Grid cells that closed obstacle paths pass through (sampled every half cell)."""
    hit = np.zeros(shape, bool)
    for path in obstacles:
        ring = np.concatenate([path, path[:1]])
        steps = int(np.ceil(np.linalg.norm(np.diff(ring, axis=0), axis=1).max() / (cell / 2))) + 1
        t = np.linspace(0.0, 1.0, steps)[None, :, None]
        dense = (ring[:-1, None] * (1 - t) + ring[1:, None] * t).reshape(-1, 2)
        index = np.round((dense - lo) / cell).astype(int)
        hit[index[:, 0], index[:, 1]] = True
    return hit


def _window(shape: tuple, di: int, dj: int) -> tuple[slice, slice]:
    """The cells of a grid whose neighbour at offset (di, dj) is inside it too."""
    return (slice(max(-di, 0), shape[0] - max(di, 0)), slice(max(-dj, 0), shape[1] - max(dj, 0)))


def _shortest(free: np.ndarray, start: tuple, goal: tuple) -> np.ndarray | None:
    """Cells (k, 2) of a shortest 8-connected path through free cells, start and goal included."""
    ids = np.arange(free.size).reshape(free.shape)
    rows, cols, lengths = [], [], []
    for di, dj in NEIGHBOURS:
        here, there = _window(free.shape, di, dj), _window(free.shape, -di, -dj)
        both = free[here] & free[there]
        rows.append(ids[here][both])
        cols.append(ids[there][both])
        lengths.append(np.full(both.sum(), np.hypot(di, dj)))
    graph = sparse.csr_matrix(
        (np.concatenate(lengths), (np.concatenate(rows), np.concatenate(cols))),
        shape=(free.size, free.size),
    )
    source, target = ids[start], ids[goal]
    distance, previous = dijkstra(graph, indices=source, return_predecessors=True)
    if not np.isfinite(distance[target]):
        return None
    path = [target]
    while path[-1] != source:
        path.append(previous[path[-1]])
    return np.stack(np.unravel_index(path[::-1], free.shape), -1)


def _pull(chain: np.ndarray, grid: _Grid) -> np.ndarray:
    """Waypoints of a grid path pulled straight: from each kept point on along the path as far
    as a straight bar stays on free cells, then without the bends that are not needed."""
    kept = [0]
    while kept[-1] < len(chain) - 1:
        here = kept[-1]
        far = here + 1
        while far + 1 < len(chain) and grid.clear(chain[here], chain[far + 1]):
            far += 1
        kept.append(far)
    k = 1
    while k < len(kept) - 1:  # then drop each bend its neighbours see past
        if grid.clear(chain[kept[k - 1]], chain[kept[k + 1]]):
            kept.pop(k)
        else:
            k += 1
    return chain[kept[1:-1]]


def bent_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers where binary links bend around the pins that block them (`assign_layers` with
    `Layout.bends`). A bent link may come near other pins: each round routes every link around
    all the pins that blocked it so far. ValueError as `assign_layers` when no round layers,
    at once when even links clear of every pin they might get around leave no layering."""
    step = largest_step(paths)
    reach = (sizes.link_width + sizes.hole_diameter) / 2 + sizes.clearance + 2 * step
    conflicts = find_conflicts(assembly, paths, sizes)
    turns = part_rotations(assembly, paths)
    passable: dict[tuple[int, int], bool] = {}  # (pin, part): might a bent part get round?
    for k, pin in enumerate(assembly.pins):
        for q in range(len(assembly.parts)):
            passable[k, q] = not _cannot_pass(assembly, paths, turns, q, pin.joint, reach)
    hopeless = [[q for q in b if not passable[k, q]] for k, b in enumerate(conflicts.blocked)]
    stack_layers(assembly, replace(conflicts, blocked=hopeless), sizes, fewest=False)  # or refused
    pins: dict[int, set[int]] = {}
    for _ in range(ROUNDS):
        before = sum(map(len, pins.values()))
        for k, parts in enumerate(conflicts.blocked):
            for q in parts:
                if passable[k, q]:
                    pins.setdefault(q, set()).add(assembly.pins[k].joint)
        if pins and sum(map(len, pins.values())) == before:
            break  # the same pins as the last round: the same routes
        routes = route_links(assembly, paths, pins, reach)
        extended, chains = with_waypoints(assembly, paths, routes)
        conflicts = find_conflicts(assembly, extended, sizes, chains)
        try:
            return replace(stack_layers(assembly, conflicts, sizes), bends=routes)
        except ValueError as exc:
            refusal = exc
    raise refusal


def _cannot_pass(
    assembly: Assembly, paths: np.ndarray, turns: np.ndarray, q: int, joint: int, reach: float
) -> bool:
    """Is no way round the pin at `joint` for part q? True for a plate (only links bend), or
    when the pin's relative path comes within reach of a joint of q or winds round one of its
    joints a different number of times than round the other (any chain between them crosses)."""
    part = assembly.parts[q]
    if part.kind != "link":
        return True
    path = relative_path(paths, turns[q], part.joints, joint)
    z = path[:, 0] + 1j * path[:, 1]
    windings = []
    for x, y in paths[list(part.joints), 0]:
        d = z - complex(x, y)
        if np.abs(d).min() < reach:
            return True
        windings.append(round(float(np.angle(np.roll(d, -1) / d).sum() / (2 * np.pi))))
    return windings[0] != windings[1]


def route_links(
    assembly: Assembly, paths: np.ndarray, pins: dict[int, set[int]], reach: float
) -> dict[int, np.ndarray]:
    """Waypoints of the binary links that can go around the pins (joints) that block them.

    Pins are taken one at a time and kept when a route around all those kept so far still
    exists; a link that no pin lets by stays straight (no entry).
    """
    turns = part_rotations(assembly, paths)
    routes: dict[int, np.ndarray] = {}
    for q, joints in sorted(pins.items()):
        part = assembly.parts[q]
        if part.kind != "link":
            continue
        ends = paths[list(part.joints), 0]
        kept: list[np.ndarray] = []
        best = None
        for joint in sorted(joints):
            obstacle = relative_path(paths, turns[q], part.joints, joint)
            found = route(ends, [*kept, obstacle], reach)
            if found is not None:
                kept.append(obstacle)
                best = found
        if best is not None and len(best):
            routes[q] = best
    return routes


def with_waypoints(
    assembly: Assembly, paths: np.ndarray, routes: dict[int, np.ndarray]
) -> tuple[np.ndarray, dict[int, list[int]]]:
    """Joint paths with the routed links' waypoint paths appended, and each routed link's
    chain as point indices (joint, waypoints..., joint) into them."""
    turns = part_rotations(assembly, paths)
    extra, chains = [paths], {}
    start = len(paths)
    for q, waypoints in sorted(routes.items()):
        a, b = assembly.parts[q].joints
        extra.append(rigid_paths(paths, turns[q], a, waypoints))
        chains[q] = [a, *range(start, start + len(waypoints)), b]
        start += len(waypoints)
    return np.concatenate(extra), chains
