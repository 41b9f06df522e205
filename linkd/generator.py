"""Random valid one-degree-of-freedom dyadic mechanisms with curated coupler curves.

Mechanisms grow joint by joint, many at once: a motor pivot and crank tip, then ground joints
and dyads in the graph matrix's order, up to a target count drawn evenly over 5..20 joints. Each
new joint is checked with `check_new_node` against its two parents' paths only (the prefix's
paths are kept, so every step solves one dyad); a failure resamples the joint's position a few
times, then its parents; a mechanism that still cannot grow is dropped and its target count is
tried again in a later round, so counts stay balanced.

Curation, so the data teaches real path synthesis: every joint stays clear of the others in the
assembly pose, every dyad keeps a transmission margin, and the end effector (the last joint) must
trace a genuine coupler curve: not a circle or circular arc (a joint hinged to ground or riding
on one rigid body with it), not a tiny path, not a nearly straight one.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from linkd.graph import ADJ, FEATURES, MAX_NODES, TYPE, VALID, XY
from linkd.validator import N_ANGLES, check_new_node


@dataclass(frozen=True)
class GeneratorSettings:
    """Sampling ranges and curation thresholds; positions live in the box [-1, 1]^2."""

    min_nodes: int = 5  # four-bars (4 joints) only trace arcs, so they are curated out
    max_nodes: int = MAX_NODES
    n_angles: int = N_ANGLES
    crank_length: tuple[float, float] = (0.1, 0.5)
    min_gap: float = 0.05  # joints at least this far apart in the assembly pose (so links too)
    min_margin: float = 0.02  # every dyad's sin^2(transmission angle) over the cycle
    ground_probability: float = 0.3  # chance that a step adds a ground joint for the next dyad
    position_tries: int = 4  # new positions for a failing joint before new parents
    parent_tries: int = 3  # parent choices before the mechanism is dropped
    arc_tolerance: float = 0.01  # circle-fit RMS residual / path RMS radius: below it, an arc
    min_path_size: float = 0.05  # path RMS radius / RMS radius of the joints
    min_path_width: float = 0.05  # minor / major principal spread of the path
    batch: int = 1024  # mechanisms grown together

    def __post_init__(self) -> None:
        if not 5 <= self.min_nodes <= self.max_nodes <= MAX_NODES:
            raise ValueError(f"node counts must satisfy 5 <= min <= max <= {MAX_NODES}")

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class Samples:
    """K curated mechanisms. The end-effector path in the graph's frame is
    `centre[:, None] + scale[:, None, None] * curves`."""

    graphs: np.ndarray  # (K, 20, 24) float32 graph matrices (linkd.graph layout)
    curves: np.ndarray  # (K, T, 2) float32 end-effector path, centroid 0, RMS radius 1
    centre: np.ndarray  # (K, 2) float32 path centroid in the graph's frame
    scale: np.ndarray  # (K,) float32 path RMS radius in the graph's frame
    n_nodes: np.ndarray  # (K,) int8 joint count
    margin: np.ndarray  # (K,) float32 min sin^2 of any transmission angle over the cycle

    def __len__(self) -> int:
        return len(self.graphs)

    @classmethod
    def concatenate(cls, parts: list[Samples]) -> Samples:
        return cls(**{k: np.concatenate([getattr(p, k) for p in parts]) for k in _FIELDS})

    def subset(self, index: np.ndarray | slice) -> Samples:
        return Samples(**{k: getattr(self, k)[index] for k in _FIELDS})


_FIELDS = ("graphs", "curves", "centre", "scale", "n_nodes", "margin")


def generate(
    count: int, seed: int | np.random.Generator, settings: GeneratorSettings | None = None
) -> Samples:
    """`count` curated mechanisms, node counts balanced over min_nodes..max_nodes.

    Deterministic for a given seed (an int or a numpy Generator) and settings.
    """
    s = settings or GeneratorSettings()
    rng = np.random.default_rng(seed)
    sizes = np.arange(s.min_nodes, s.max_nodes + 1)
    queue = rng.permutation(np.resize(sizes, count))
    if count == 0:
        return _grow(queue, rng, s)[0]
    parts = []
    for _ in range(100):
        if len(queue) == 0:
            return Samples.concatenate(parts)
        failed = []
        for start in range(0, len(queue), s.batch):
            targets = queue[start : start + s.batch]
            samples, ok = _grow(targets, rng, s)
            parts.append(samples)
            failed.append(targets[~ok])
        queue = np.concatenate(failed)
    raise RuntimeError(f"could not grow mechanisms of {sorted(set(queue.tolist()))} joints")


def _grow(targets: np.ndarray, rng: np.random.Generator, s: GeneratorSettings) -> tuple:
    """Grow one mechanism per target count; returns the curated samples and the success mask."""
    bsz, n = len(targets), s.max_nodes
    pos = np.zeros((bsz, MAX_NODES, 2), np.float32)
    fixed = np.zeros((bsz, MAX_NODES), bool)
    links = np.zeros((bsz, MAX_NODES, MAX_NODES), bool)  # [b, k, j]: k hangs on earlier j
    paths = np.zeros((bsz, n, s.n_angles, 2), np.float32)  # every joint's path, for dyads
    margin = np.ones(bsz, np.float32)
    alive = np.ones(bsz, bool)

    # Motor: a pivot anywhere in the box and a crank tip that also lies in it.
    fixed[:, 0] = True
    pos[:, 0] = rng.uniform(-1, 1, (bsz, 2))
    links[:, 1, 0] = True
    todo = np.arange(bsz)
    while len(todo):
        length = rng.uniform(*s.crank_length, len(todo))
        angle = rng.uniform(0, 2 * np.pi, len(todo))
        pos[todo, 1] = pos[todo, 0] + length[:, None] * np.stack([np.cos(angle), np.sin(angle)], 1)
        todo = todo[np.abs(pos[todo, 1]).max(1) > 1]
    for k in range(2):
        _, paths[:, k], _ = check_new_node(
            paths[:, :k], fixed[:, :k], fixed[:, k], pos[:, k], links[:, k, :k]
        )

    has_ground = np.zeros(bsz, bool)  # a ground joint besides the motor pivot
    for t in range(2, n):
        active = np.flatnonzero(alive & (t < targets))
        if len(active) == 0:
            break
        last = targets[active] == t + 1
        after_ground = fixed[active, t - 1]
        # A ground joint must be followed by a dyad that is not the end effector.
        may_ground = (targets[active] >= t + 3) & ~after_ground
        chance = np.where(has_ground[active], s.ground_probability, 2 * s.ground_probability)
        must = ~has_ground[active] & (targets[active] == t + 3)
        ground = may_ground & ((rng.random(len(active)) < chance) | must)
        state = (pos, fixed, links, paths, margin)
        placed = _place_ground(active[ground], t, state, rng, s)
        alive[active[ground][~placed]] = False
        placed = _place_dyad(active[~ground], t, last[~ground], state, rng, s)
        alive[active[~ground][~placed]] = False
        has_ground[active[ground]] = True

    rows = np.flatnonzero(alive)
    ee = targets[rows] - 1
    samples = _samples(pos[rows], fixed[rows], links[rows], paths[rows, ee], targets[rows],
                       margin[rows], s)  # fmt: skip
    return samples, alive


def _place_ground(rows, t, state, rng, s) -> np.ndarray:
    """Joint t of `rows` is a ground joint somewhere clear of the others; returns success."""
    pos, fixed, _, paths, _ = state
    ok = np.zeros(len(rows), bool)
    todo = np.arange(len(rows))
    for _ in range(s.position_tries * s.parent_tries):
        b = rows[todo]
        xy = rng.uniform(-1, 1, (len(b), 2)).astype(np.float32)
        good = _clear(pos[b, :t], xy, s.min_gap)
        accept = todo[good]
        ok[accept] = True
        fixed[rows[accept], t] = True
        pos[rows[accept], t] = xy[good]
        paths[rows[accept], t] = xy[good, None, :]
        todo = todo[~good]
        if len(todo) == 0:
            break
    return ok


def _place_dyad(rows, t, last, state, rng, s) -> np.ndarray:
    """Joint t of `rows` hangs on two earlier joints (the end effector when `last`); returns
    success. Retries: new positions first, then new parents."""
    pos, fixed, links, paths, margin = state
    ok = np.zeros(len(rows), bool)
    todo = np.arange(len(rows))
    for _ in range(s.parent_tries):
        parents = _choose_parents(fixed[rows[todo], :t], last[todo], rng)
        for _ in range(s.position_tries):
            b = rows[todo]
            xy = rng.uniform(-1, 1, (len(b), 2)).astype(np.float32)
            pair = paths[b[:, None], parents]  # (m, 2, T, 2), parents ascending
            pair_fixed = fixed[b[:, None], parents]
            both = np.ones((len(b), 2), bool)
            good, path, m = check_new_node(pair, pair_fixed, np.zeros(len(b), bool), xy, both)
            good &= (m >= s.min_margin) & _clear(pos[b, :t], xy, s.min_gap)
            ee = np.flatnonzero(last[todo] & good)
            if len(ee):
                joints = np.concatenate([pos[b[ee], :t], xy[ee, None]], 1)
                good[ee] = coupler_curve(path[ee], joints, s)
            accept = todo[good]
            ok[accept] = True
            r = rows[accept]
            pos[r, t] = xy[good]
            links[r[:, None], t, parents[good]] = True
            paths[r, t] = path[good]
            margin[r] = np.minimum(margin[r], m[good])
            todo, parents = todo[~good], parents[~good]
            if len(todo) == 0:
                return ok
    return ok


def _choose_parents(fixed: np.ndarray, last: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(m, 2) ascending parents among t earlier joints: one moving joint and any other one.

    A ground joint placed just before must be used (that is why it is there); the end effector
    hangs on two moving joints, since a joint hinged to ground only traces an arc.
    """
    t = fixed.shape[1]
    moving = ~fixed
    first = _pick(moving, rng)
    other = (np.arange(t) != first[:, None]) & (moving | ~last[:, None])
    second = np.where(fixed[:, -1], t - 1, _pick(other, rng))
    return np.sort(np.stack([first, second], 1), 1)


def _pick(mask: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One index per row, uniform among the row's True entries."""
    return np.argmax(rng.random(mask.shape) * mask, 1)


def _clear(others: np.ndarray, xy: np.ndarray, gap: float) -> np.ndarray:
    """(m,) the new positions keep `gap` from every earlier joint."""
    d2 = ((others - xy[:, None]) ** 2).sum(-1).min(1)
    return d2 >= gap * gap


def coupler_curve(paths: np.ndarray, joints: np.ndarray, s: GeneratorSettings) -> np.ndarray:
    """(B,) which closed paths (B, T, 2) are genuine coupler curves of mechanisms with joints
    (B, n, 2): not a circle or circular arc, not tiny, not nearly straight."""
    p = paths.astype(np.float64)
    centred = p - p.mean(1, keepdims=True)
    rms = np.sqrt((centred**2).sum(-1).mean(1))
    body = joints - joints.mean(1, keepdims=True)
    size = np.sqrt((body**2).sum(-1).mean(1))
    big = rms >= s.min_path_size * size
    unit = centred / np.maximum(rms, 1e-12)[:, None, None]
    spread = np.linalg.eigvalsh(np.einsum("bti,btj->bij", unit, unit))  # ascending
    minor, major = np.maximum(spread[:, 0], 0), np.maximum(spread[:, 1], 1e-30)
    wide = np.sqrt(minor / major) >= s.min_path_width
    return big & wide & (circle_residual(unit) >= s.arc_tolerance)


def circle_residual(paths: np.ndarray) -> np.ndarray:
    """(B,) RMS distance of each path (B, T, 2) to its least-squares circle (algebraic fit),
    in the path's own units."""
    x, y = paths[..., 0], paths[..., 1]
    design = np.stack([x, y, np.ones_like(x)], -1)
    rhs = -(x * x + y * y)
    normal = np.einsum("bti,btj->bij", design, design) + 1e-12 * np.eye(3)  # a point: no crash
    coef = np.linalg.solve(normal, np.einsum("bti,bt->bi", design, rhs)[..., None])[..., 0]
    centre = -coef[:, :2] / 2
    radius = np.sqrt(np.maximum((centre**2).sum(-1) - coef[:, 2], 0))
    distance = np.sqrt(((paths - centre[:, None]) ** 2).sum(-1))
    return np.sqrt(((distance - radius[:, None]) ** 2).mean(1))


def _samples(pos, fixed, links, path, n_nodes, margin, s: GeneratorSettings) -> Samples:
    """Pack grown mechanisms into graph matrices and normalised end-effector curves."""
    k, n = len(pos), MAX_NODES
    valid = np.arange(n) < np.asarray(n_nodes)[:, None]
    graphs = np.full((k, n, FEATURES), -1, np.float32)
    graphs[..., VALID] = valid
    graphs[..., TYPE] = np.where(valid, fixed, -1)
    graphs[..., XY] = np.where(valid[..., None], pos, 0)
    lower = np.tril(np.ones((n, n), bool), -1) & valid[:, :, None]
    graphs[..., ADJ] = np.where(lower, links, -1)
    centre = path.mean(1)
    scale = np.sqrt(((path - centre[:, None]) ** 2).sum(-1).mean(1))
    curves = (path - centre[:, None]) / np.maximum(scale, 1e-12)[:, None, None]
    return Samples(
        graphs,
        curves.astype(np.float32),
        centre.astype(np.float32),
        scale.astype(np.float32),
        np.asarray(n_nodes, np.int8),
        np.asarray(margin, np.float32),
    )
