"""Drop the joints that add nothing to the end effector's motion.

Growing a design by coupler points (`rounds`) leaves chains behind: the new end effector hangs
on the old one and another joint of the same rigid body, so the old end effector stays only as
a support, a hole in a plate that a builder drills for nothing, and a short link that makes
the loops stiff to simulate. Every joint rigid with a body (both its parents on that body) can
hang on any two earlier joints of the body instead, with the same motion; hung on the body's
first two joints, the supports it used fall out, and so does every joint the end effector no
longer needs. The end effector's path stays exactly as it was.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from linkd.batch import LinkageBatch, ancestors

MIN_SIN2 = 0.1  # a joint is hung on new supports only where its triangle is this far from flat
MIN_REACH = 0.1  # nor closer than this to either of them (normalised frame: RMS radius 1)


def pruned(batch: LinkageBatch) -> LinkageBatch:
    """The linkages (valid joints first, in dyadic order) with rigid joints hung on their body's
    first joints where that is well-conditioned, and the joints the end effector then does not
    need removed; the motor pivot and crank tip stay joints 0 and 1, the order is kept. (A
    Python loop over the linkages: for the few designs a round or delivery handles.)"""
    out = batch.subset(np.arange(len(batch)))  # a copy
    for row in range(len(out)):
        _rehang(out, row)
    needed = ancestors(out.adjacency, out.end_effector) & out.valid
    needed[:, :2] = out.valid[:, :2]
    order = np.argsort(~needed, axis=1, kind="stable")  # needed joints first, in order
    valid = np.take_along_axis(needed, order, 1)
    adjacency = np.take_along_axis(out.adjacency, order[:, :, None], 1)
    adjacency = np.take_along_axis(adjacency, order[:, None, :], 2)
    end_effector = np.argmax(order == out.end_effector[:, None], 1)
    positions = np.take_along_axis(out.positions, order[:, :, None], 1)
    fixed = np.take_along_axis(out.fixed, order, 1) & valid
    adjacency &= valid[:, :, None] & valid[:, None, :]
    return LinkageBatch(positions, fixed, valid, adjacency, end_effector)


def _rehang(batch: LinkageBatch, row: int) -> None:
    """Hang each moving joint of linkage `row` whose two parents lie on one rigid body (kept as
    lists of joints, first joints first) on the body's first two joints, or its best-conditioned
    earlier pair, in place."""
    n = int(batch.valid[row].sum())
    adjacency, positions, fixed = batch.adjacency[row], batch.positions[row], batch.fixed[row]
    bodies: list[list[int]] = []
    for k in range(1, n):
        parents = [int(j) for j in np.flatnonzero(adjacency[k, :k])]
        if fixed[k] or len(parents) != 2:
            bodies += [[p, k] for p in parents]
            continue
        shared = [body for body in bodies if parents[0] in body and parents[1] in body]
        if not shared:
            bodies += [[parents[0], k], [parents[1], k]]
            continue
        body = sorted(set().union(*shared))
        bodies = [*(b for b in bodies if b not in shared), [*body, k]]
        supports = _supports(positions, body, k)
        if supports is not None and fixed[list(supports)].sum() < 2:
            adjacency[k, parents] = adjacency[parents, k] = False
            adjacency[k, list(supports)] = adjacency[list(supports), k] = True


def _supports(positions: np.ndarray, body: list[int], k: int) -> tuple[int, int] | None:
    """The pair of the body's joints (all earlier than k) to hang joint k on: the first two
    when k's triangle with them is well-conditioned, else the best-conditioned pair, else None."""
    best, score = None, MIN_SIN2
    for a, b in combinations(body, 2):
        u, v = positions[a] - positions[k], positions[b] - positions[k]
        lu, lv = np.hypot(*u), np.hypot(*v)
        if min(lu, lv) < MIN_REACH:
            continue
        sin2 = ((u[0] * v[1] - u[1] * v[0]) / (lu * lv)) ** 2
        if (a, b) == tuple(body[:2]) and sin2 >= MIN_SIN2:
            return a, b
        if sin2 >= score:
            best, score = (a, b), sin2
    return best
