"""The search around the best designs: jittered copies of the best few, refined in turn.

Refinement settles each candidate in the nearest local minimum of the curve error. Near the
best of them there are often better ones a step away, across a ridge L-BFGS does not cross; a
round samples that neighbourhood by moving every joint of the best few designs at random, at a
few scales, and refines the copies that are still valid mechanisms (basin hopping, batched).
"""

from __future__ import annotations

import numpy as np

from linkd.batch import LinkageBatch

from .propose import Candidates
from .select import diverse_best


def around(
    candidates: Candidates, count: int, copies: int, spread: float, seed: int
) -> LinkageBatch:
    """`copies` jittered copies of each of the best `count` candidates of distinct topologies
    (refined or not, by their latest error); joints move by Gaussian steps of `spread` times
    1/4, 1/2 and 1 in turn."""
    order = np.argsort(candidates.chamfer, kind="stable")
    order = order[np.isfinite(candidates.chamfer[order])]
    best = np.array(diverse_best(candidates.batch, order, count, 1), dtype=int)
    rows = np.repeat(best, copies)
    batch = candidates.batch.subset(rows)
    rng = np.random.default_rng(seed)
    scale = spread * np.resize([0.25, 0.5, 1.0], len(rows))[:, None, None]
    step = rng.normal(size=batch.positions.shape) * scale
    batch.positions = batch.positions + np.where(batch.valid[..., None], step, 0)
    return batch
