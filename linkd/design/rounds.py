"""The search around the best designs: grown copies of the best few, refined in turn.

Refinement settles each candidate in the nearest local minimum of the curve error, with its
topology fixed. A round takes the best few designs a step further. Half the copies gain one
joint, rigid with one of its links (hung on the link's two joints, so the copy is valid
whatever the link's motion) and made the end effector. Its path is a coupler curve of that
link's body: on half of these it starts near the old end effector on one of its links, so
refinement begins close to the best fit so far with the end effector free to move onto a
neighbouring body, and anywhere about any link on the rest. The other half gain a dyad, a new
loop: the new end effector hangs on the old one and on a new coupler point of a neighbouring
body, sized so that it starts near the old path, and refinement can grow the loop's motion
into the corners and loops a coupler curve of the same bodies cannot follow. Many copies are
made (a copy is cheap to place on the target, dear to refine) and only the best placed are
refined. Designs with no room for a joint more have their joints moved at random instead
(basin hopping). The designs are pruned first (`prune`): the supports of an earlier grown
joint that nothing else needs fall out, so growth does not pile up idle joints. Only designs
that can be built are searched around: a neighbourhood of a design the export refuses mostly
holds designs it refuses too, which delivery would pass over.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from linkd.batch import LinkageBatch
from linkd.kinematics import dyad, ops_for
from linkd.validator import validate

from .propose import Candidates, joined
from .prune import pruned
from .select import topology_key

MAX_CHECKS = 3  # topologies asked about, per design searched around
DYAD_SHARE = 0.5  # share of the copies with room for two joints more grown by a dyad
DYAD_ALONG = (0.02, 0.2)  # the new coupler point's offset from Q along its link, in its lengths
DYAD_ACROSS = (0.07, 0.2)  # and across it, either way (its triangle with the link is no sliver)
DYAD_SLACK = 0.7  # cosine of the new end effector's transmission angle at its extremes
NEAR_END_EFFECTOR = 0.5  # share of grown copies whose new joint starts near the end effector


def around(
    candidates: Candidates,
    count: int,
    copies: int,
    spread: float,
    seed: int,
    buildable: Callable[[LinkageBatch, int], bool] = lambda batch, row: True,
    max_joints: int | None = None,
) -> LinkageBatch:
    """`copies` copies of each of the best `count` candidates of distinct topologies (refined or
    not, by their latest error), pruned, that are `buildable` (a topology whose best design is
    not is passed over): grown by a coupler point where they have fewer than `max_joints`
    joints (and the batch room for one more), on a DYAD_SHARE of those with room for two by a
    dyad (`with_dyad`), else with joints moved by Gaussian steps of `spread` times 1/4, 1/2
    and 1 in turn."""
    order = np.argsort(candidates.chamfer, kind="stable")
    order = order[np.isfinite(candidates.chamfer[order])]
    best, seen = [], set()
    for row in order:
        key = topology_key(candidates.batch, int(row))
        if key in seen:
            continue
        seen.add(key)
        if len(seen) > MAX_CHECKS * count or len(best) == count:
            break
        design = pruned(candidates.batch.subset([int(row)]))
        if buildable(design, 0):
            best.append(design)
    if not best:
        return candidates.batch.subset(np.zeros(0, int))
    designs = joined(best)
    motion = validate(designs, keep_motion=True, backend="numpy").motion
    copy_of = np.repeat(np.arange(len(best)), copies)
    batch = designs.subset(copy_of)
    rng = np.random.default_rng(seed)
    limit = min(max_joints or batch.valid.shape[1], batch.valid.shape[1])
    room = (batch.valid.sum(1) < limit) & _moving_links(batch).any((1, 2))
    dyad = room & (batch.valid.sum(1) + 2 <= limit) & (rng.random(len(batch)) < DYAD_SHARE)
    paths = np.stack([motion.x, motion.y], -1)[copy_of[dyad]]  # (copies, N, T, 2)
    return joined([with_coupler_point(batch.subset(np.flatnonzero(room & ~dyad)), rng),
                   with_dyad(batch.subset(np.flatnonzero(dyad)), paths, rng),
                   jittered(batch.subset(np.flatnonzero(~room)), spread, rng)])  # fmt: skip


def with_dyad(batch: LinkageBatch, paths: np.ndarray, rng: np.random.Generator) -> LinkageBatch:
    """The linkages, each with two joints more and a new loop (`paths`: (B, N, T, 2) every
    joint's path): a coupler point A on a link (Q, R) of a neighbouring body, a little off the
    joint Q that body shares with the end effector E's, and a new end effector hung on E and
    A. E's distance to A varies only as much as A sits off Q, and the two new links are sized
    from its least and most over the revolution (`_dyad_links`), so the new path starts near
    the old one. Each row needs room for two joints more; rows with no such link are
    dropped."""
    b, n = batch.valid.shape
    rows, ee = np.arange(b), batch.end_effector
    on_ee = batch.adjacency[rows, ee]  # (B, N) joints E hangs on or that hang on E
    off_ee = ~on_ee & (np.arange(n) != ee[:, None])
    moves = ~(batch.fixed[:, :, None] & batch.fixed[:, None, :])
    pool = batch.adjacency & moves & on_ee[:, :, None] & off_ee[:, None, :]  # (Q, R) links
    pick = np.where(pool, rng.random(pool.shape), -1.0).reshape(b, n * n).argmax(1)
    q, r = np.unravel_index(pick, (n, n))
    along = rng.uniform(*DYAD_ALONG, b)
    across = rng.uniform(*DYAD_ACROSS, b) * rng.choice([-1.0, 1.0], b)
    anchor_path = _off_link(paths, q, r, along, across)  # (B, T, 2)
    distance = np.linalg.norm(anchor_path - paths[rows, ee], axis=-1)  # (B, T)
    short, long = _dyad_links(distance.min(1), distance.max(1))
    new = batch.valid.sum(1)  # valid joints come first: A, then the end effector
    grown = _hung(batch, new, q, r, _off_link(batch.positions, q, r, along, across))
    e, a = grown.positions[rows, ee], grown.positions[rows, new]
    side = rng.choice([-1.0, 1.0], b)
    x, y, _ = dyad(e[:, 0], e[:, 1], a[:, 0], a[:, 1], short**2, long**2, side, ops_for(e))
    grown = _hung(grown, new + 1, ee, new, np.stack([x, y], 1))
    grown.end_effector = new + 1
    return grown.subset(np.flatnonzero(pool.any((1, 2))))


def _dyad_links(nearest: np.ndarray, farthest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two links (short, long) of a dyad whose parents' distance runs from `nearest` to
    `farthest`: the transmission angle's cosine is -DYAD_SLACK at one end and DYAD_SLACK at
    the other (by the law of cosines), or the links are equal where that cannot be."""
    lo, hi = nearest**2, farthest**2
    total = (lo + hi) / 2  # short^2 + long^2
    product = np.minimum((hi - lo) / (4 * DYAD_SLACK), total / 2)  # short * long
    root = np.sqrt(total**2 - 4 * product**2)
    return np.sqrt((total - root) / 2), np.sqrt((total + root) / 2)


def _hung(batch: LinkageBatch, new: np.ndarray, first: np.ndarray, second: np.ndarray,
          position: np.ndarray) -> LinkageBatch:  # fmt: skip
    """A copy of the batch with each row's joint `new` at `position`, moving, linked to its
    joints `first` and `second`."""
    grown = batch.subset(np.arange(len(batch)))
    rows = np.arange(len(batch))
    grown.positions[rows, new] = position
    grown.valid[rows, new] = True
    grown.fixed[rows, new] = False
    for end in (first, second):
        grown.adjacency[rows, new, end] = grown.adjacency[rows, end, new] = True
    return grown


def _off_link(points: np.ndarray, first: np.ndarray, second: np.ndarray, along: np.ndarray,
              across: np.ndarray) -> np.ndarray:  # fmt: skip
    """Each row's point `along` its link from joint `first` to `second` and `across` it, in
    the link's lengths, from the joints' positions (B, N, 2) or paths (B, N, T, 2)."""
    rows = np.arange(len(points))
    link = points[rows, second] - points[rows, first]
    normal = np.stack([-link[..., 1], link[..., 0]], -1)
    return points[rows, first] + _times(link, along) + _times(normal, across)


def _times(vectors: np.ndarray, factors: np.ndarray) -> np.ndarray:
    """Each row's vectors, (B, 2) or (B, T, 2), times its factor."""
    return vectors * factors.reshape(-1, *([1] * (vectors.ndim - 1)))


def with_coupler_point(batch: LinkageBatch, rng: np.random.Generator) -> LinkageBatch:
    """The linkages (each with room for a joint more and a link between moving joints), each
    with a new last joint, its end effector, hung on both ends of one such link: near the old
    end effector on one of its links (a NEAR_END_EFFECTOR share), else anywhere about any."""
    b, n = batch.valid.shape
    links = _moving_links(batch)
    ee = batch.end_effector
    is_ee = np.arange(n) == ee[:, None]
    at_ee = links & (is_ee[:, :, None] | is_ee[:, None, :])
    near = (rng.random(b) < NEAR_END_EFFECTOR) & at_ee.any((1, 2))
    pool = np.where(near[:, None, None], at_ee, links)
    pick = np.where(pool, rng.random(pool.shape), -1.0).reshape(b, n * n).argmax(1)
    first, second = np.unravel_index(pick, (n, n))
    swap = second == ee  # start from the end effector's end
    first, second = np.where(swap, second, first), np.where(swap, first, second)
    s = np.where(near, rng.normal(0, 0.15, b), rng.uniform(-0.5, 1.5, b))
    t = np.where(near, rng.normal(0, 0.15, b), rng.normal(0, 0.5, b))
    new = batch.valid.sum(1)  # valid joints come first
    grown = _hung(batch, new, first, second, _off_link(batch.positions, first, second, s, t))
    grown.end_effector = new
    return grown


def jittered(batch: LinkageBatch, spread: float, rng: np.random.Generator) -> LinkageBatch:
    """The linkages with every joint moved by Gaussian steps of `spread` times 1/4, 1/2 and 1 in
    turn."""
    scale = spread * np.resize([0.25, 0.5, 1.0], len(batch))[:, None, None]
    step = rng.normal(size=batch.positions.shape) * scale
    batch.positions = batch.positions + np.where(batch.valid[..., None], step, 0)
    return batch


def _moving_links(batch: LinkageBatch) -> np.ndarray:
    """(B, N, N) links between two moving joints, each once (upper triangle)."""
    moving = batch.valid & ~batch.fixed
    return np.triu(batch.adjacency, 1) & moving[:, :, None] & moving[:, None, :]
