"""The search around the best designs: grown copies of the best few, refined in turn.

Refinement settles each candidate in the nearest local minimum of the curve error, with its
topology fixed. A round takes the best few designs a step further: each copy gains one joint,
rigid with one of its links (hung on the link's two joints, so the copy is valid whatever the
link's motion) and made the end effector. Its path is a coupler curve of that link's body: on
half the copies it starts near the old end effector on one of its links, so refinement begins
close to the best fit so far with the end effector free to move onto a neighbouring body, and
anywhere about any link on the rest. Many copies are made (a coupler curve is cheap to place
on the target, dear to refine) and only the best placed are refined. Designs with no room for
a joint more have their joints moved at random instead (basin hopping). The designs are
pruned first (`prune`): the supports of an earlier grown joint that nothing else needs fall
out, so growth does not pile up idle joints. Only designs that can be built are searched
around: a neighbourhood of a design the export refuses mostly holds designs it refuses too,
which delivery would pass over.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from linkd.batch import LinkageBatch

from .propose import Candidates, joined
from .prune import pruned
from .select import topology_key

MAX_CHECKS = 3  # topologies asked about, per design searched around
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
    joints (and the batch room for one more), else with joints moved by Gaussian steps of
    `spread` times 1/4, 1/2 and 1 in turn."""
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
    batch = joined(best).subset(np.repeat(np.arange(len(best)), copies))
    rng = np.random.default_rng(seed)
    limit = min(max_joints or batch.valid.shape[1], batch.valid.shape[1])
    room = (batch.valid.sum(1) < limit) & _moving_links(batch).any((1, 2))
    grown = with_coupler_point(batch.subset(np.flatnonzero(room)), rng)
    return joined([grown, jittered(batch.subset(np.flatnonzero(~room)), spread, rng)])


def with_coupler_point(batch: LinkageBatch, rng: np.random.Generator) -> LinkageBatch:
    """The linkages (each with room for a joint more and a link between moving joints), each
    with a new last joint, its end effector, hung on both ends of one such link: near the old
    end effector on one of its links (a NEAR_END_EFFECTOR share), else anywhere about any."""
    b, n = batch.valid.shape
    rows = np.arange(b)
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
    start = batch.positions[rows, first]
    along = batch.positions[rows, second] - start
    across = np.stack([-along[:, 1], along[:, 0]], 1)
    s = np.where(near, rng.normal(0, 0.15, b), rng.uniform(-0.5, 1.5, b))
    t = np.where(near, rng.normal(0, 0.15, b), rng.normal(0, 0.5, b))
    new = batch.valid.sum(1)  # valid joints come first
    batch.positions[rows, new] = start + s[:, None] * along + t[:, None] * across
    batch.valid[rows, new] = True
    batch.fixed[rows, new] = False
    for ends in (first, second):
        batch.adjacency[rows, new, ends] = batch.adjacency[rows, ends, new] = True
    batch.end_effector = new
    return batch


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
