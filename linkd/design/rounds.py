"""The search around the best designs: jittered copies of the best few, refined in turn.

Refinement settles each candidate in the nearest local minimum of the curve error. Near the
best of them there are often better ones a step away, across a ridge L-BFGS does not cross; a
round samples that neighbourhood by moving every joint of the best few designs at random, at a
few scales, and refines the copies that are still valid mechanisms (basin hopping, batched).
Only designs that can be built are searched around: a neighbourhood of a design the export
refuses mostly holds designs it refuses too, which delivery would pass over.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from linkd.batch import LinkageBatch

from .propose import Candidates
from .select import topology_key

MAX_CHECKS = 3  # topologies asked about, per design searched around


def around(
    candidates: Candidates,
    count: int,
    copies: int,
    spread: float,
    seed: int,
    buildable: Callable[[LinkageBatch, int], bool] = lambda batch, row: True,
) -> LinkageBatch:
    """`copies` jittered copies of each of the best `count` candidates of distinct topologies
    (refined or not, by their latest error) that are `buildable` (a topology whose best design
    is not is passed over); joints move by Gaussian steps of `spread` times 1/4, 1/2 and 1 in
    turn."""
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
        if buildable(candidates.batch, int(row)):
            best.append(int(row))
    rows = np.repeat(np.array(best, dtype=int), copies)
    batch = candidates.batch.subset(rows)
    rng = np.random.default_rng(seed)
    scale = spread * np.resize([0.25, 0.5, 1.0], len(rows))[:, None, None]
    step = rng.normal(size=batch.positions.shape) * scale
    batch.positions = batch.positions + np.where(batch.valid[..., None], step, 0)
    return batch
