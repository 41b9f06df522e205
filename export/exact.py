"""Layers by an exact search (a mixed-integer program, scipy's HiGHS) when the quick searches of
`stacking` find no flat order: pieces on layers, pins that avoid what passes near them, ground
pins in the base or the cover, and pairs of pieces that should share a layer (the two halves of
a link, which otherwise need a spacer between them).

Every either/or is a binary with a big-M pair of inequalities: two conflicting pieces sit one
above the other; a piece near a pin lies above all its members or below all of them; a ground
pin stands in the base (what passes near it lies above its members) or hangs from the cover
(below them). The objective is the layer count first, then the pairs split.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TIME_LIMIT = 20.0  # seconds; the best layering found by then is used (not proved minimal)


@dataclass(frozen=True)
class ExactProblem:
    """Pieces 0..n-1 (layers 1..n); pins as (members, blocked) lists of pieces."""

    conflict: np.ndarray  # (n, n) bool: the two pieces may not share a layer
    pins: list[tuple[list[int], list[int]]]
    grounded: set[int]  # pins that also hold the ground (base or cover)
    pairs: list[tuple[int, int]]  # pieces better on one layer (each split costs a spacer)


@dataclass(frozen=True)
class ExactLayers:
    layers: list[int]  # 1..stack per piece
    cover: set[int]  # grounded pins held by the cover over the stack
    stack: int
    minimal: bool  # proved optimal


class _Rows:
    """Sparse inequality rows `sum(c x) >= lower`, built one at a time."""

    def __init__(self) -> None:
        self.rows: list[int] = []
        self.cols: list[int] = []
        self.vals: list[float] = []
        self.lower: list[float] = []

    def add(self, terms: dict[int, float], lower: float) -> None:
        row = len(self.lower)
        for col, val in terms.items():
            self.rows.append(row)
            self.cols.append(col)
            self.vals.append(val)
        self.lower.append(lower)


def solve_exact(problem: ExactProblem, time_limit: float = TIME_LIMIT) -> ExactLayers | None:
    """The layering with the fewest layers (then the fewest split pairs), or None if none
    exists (or none was found in time)."""
    from scipy.optimize import Bounds, LinearConstraint, milp
    from scipy.sparse import coo_matrix

    n = len(problem.conflict)
    big = n + 1
    z = list(range(n))  # layer of each piece
    top, used = n, n + 1  # top layer of the stack; whether the cover is used
    count = n + 2
    rows = _Rows()

    def binary() -> int:
        nonlocal count
        count += 1
        return count - 1

    def apart(low: int, high: int, flag: int, when: int) -> None:
        """z[high] >= z[low] + 1 whenever the binary `flag` equals `when`."""
        sign = 1 if when == 1 else -1
        rows.add({z[high]: 1, z[low]: -1, flag: -big * sign}, 1 - big * (when == 1))

    for p in range(n):
        rows.add({top: 1, z[p]: -1}, 0)
    for p, q in zip(*np.nonzero(np.triu(problem.conflict, 1))):
        flag = binary()
        apart(p, q, flag, 1)  # flag 1: q above p
        apart(q, p, flag, 0)
    cover_flags = {}
    for k, (members, blocked) in enumerate(problem.pins):
        if not blocked:
            continue
        if k in problem.grounded:
            cover_flags[k] = flag = cover_flags.get(k, binary())
            above_when = 0  # standing in the base: what passes near lies above
        else:
            flag, above_when = binary(), 1
        for q in blocked:
            for m in members:
                apart(m, q, flag, above_when)
                apart(q, m, flag, 1 - above_when)
    for flag in cover_flags.values():
        rows.add({used: 1, flag: -1}, 0)
    steps = []
    for a, b in problem.pairs:
        step = binary()
        steps.append(step)
        rows.add({step: big, z[a]: -1, z[b]: 1}, 0)
        rows.add({step: big, z[b]: -1, z[a]: 1}, 0)
    weight = len(steps) + 1
    cost = np.zeros(count)
    cost[top] = cost[used] = weight
    cost[steps] = 1
    lower, upper = np.zeros(count), np.ones(count)
    lower[[*z, top]], upper[[*z, top]] = 1, n
    matrix = coo_matrix((rows.vals, (rows.rows, rows.cols)), shape=(len(rows.lower), count))
    result = milp(cost, integrality=np.ones(count), bounds=Bounds(lower, upper),
                  constraints=LinearConstraint(matrix.tocsr(), rows.lower, np.inf),
                  options={"time_limit": time_limit})  # fmt: skip
    if result.x is None:
        return None
    x = np.round(result.x).astype(int)
    layers = x[z]
    used_layers = sorted(set(layers.tolist()))  # close any gaps in the numbering
    renumber = {level: k + 1 for k, level in enumerate(used_layers)}
    cover = {k for k, flag in cover_flags.items() if x[flag]}
    return ExactLayers([renumber[int(v)] for v in layers], cover, len(used_layers),
                       result.status == 0)  # fmt: skip
