"""Exact answers to the two questions of stacking parts into layers, from a SAT solver: is
there an order that keeps every pin clear, and a stack of k layers that does?

Both are small satisfiability problems (tens of parts, a literal per pair or per part and
layer), settled in milliseconds and proved either way. A budgeted depth-first search spends
its whole budget where the answer is no (most of what a refused mechanism cost before) and
misses some answers that are yes.

A pin's rule, for each part kept off it: placed before all the pin's plates or after all of
them ("between", the pins of moving parts only), after all of them (a pin standing in the
base, open from the start), or before all of them (one hanging from the cover, never closed).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from pysat.solvers import Solver

SOLVER = "minisat22"  # small problems: the quickest to start and to answer


def exact_order(n: int, rules: list[tuple]) -> list[int] | None:
    """A pin-safe order of n parts (bottom up) under the pins' `rules` (`stacking.PinState`),
    or None: none exists. A literal per pair says which comes first; the triples that make it
    a total order are added only where a model breaks them (most never come up), until one
    has no cycle of three, and so none at all (a tournament)."""
    if n <= 1:
        return list(range(n))
    index = _pairs(n)
    clauses = []
    for members, blocked, rule in rules:
        for b in blocked:
            if rule == "after":
                clauses += [[int(index[m, b])] for m in members]
            elif rule == "before":
                clauses += [[int(index[b, m])] for m in members]
            else:
                clauses += [[-int(index[m, b]), -int(index[b, o])]
                            for m in members for o in members if m != o]  # fmt: skip
    with Solver(name=SOLVER, bootstrap_with=clauses) as solver:
        while True:
            if not solver.solve():
                return None
            true = np.zeros(n * (n - 1) // 2 + 1, bool)
            model = np.array(solver.get_model() or [], int)
            true[model[model > 0]] = True
            before = np.where(index > 0, true[np.abs(index)], ~true[np.abs(index)]) & (index != 0)
            cycles = _cycles(before)
            if not len(cycles):
                return np.argsort(-before.sum(1), kind="stable").tolist()  # most above it: first
            a, b, c = cycles.T
            ab, bc, ac = index[a, b], index[b, c], index[a, c]
            for clause in np.concatenate([np.stack([-ab, -bc, ac], 1),
                                          np.stack([ab, bc, -ac], 1)]).tolist():  # fmt: skip
                solver.add_clause(clause)


def _cycles(before: np.ndarray) -> np.ndarray:
    """(k, 3) the triples a < b < c of parts that `before` orders in a cycle, either way."""
    ab, bc, ca = before[:, :, None], before[None, :, :], before.T[:, None, :]
    cyclic = (ab & bc & ca) | (~ab & ~bc & ~ca)
    a, b, c = np.nonzero(cyclic)
    keep = (a < b) & (b < c)
    return np.stack([a[keep], b[keep], c[keep]], 1)


@lru_cache(maxsize=8)
def _pairs(n: int) -> np.ndarray:
    """(n, n) the literal "p before q": k numbering the pairs p < q, -k for p > q (0: p = q)."""
    index = np.zeros((n, n), int)
    i, j = np.triu_indices(n, 1)
    index[i, j] = np.arange(1, len(i) + 1)
    index[j, i] = -index[i, j]
    return index


def exact_stack(conflict: np.ndarray, rules: list[tuple], stack: int) -> list[int] | None:
    """Layers 1..stack of the parts, parts that `conflict` never on one layer and every pin's
    span clear of the parts kept off it (`rules`), or None: there are none. (A part kept off a
    pin comes near each of its plates, so the two never share a layer anyway.)

    Part p's layer L is written in order: the literal (p, l) says L <= l, for l < stack."""
    n = len(conflict)
    at = np.arange(n * (stack - 1)).reshape(n, stack - 1) + 1
    no, yes = n * (stack - 1) + 1, n * (stack - 1) + 2  # constant false and true

    def upto(p: int, level: int) -> int:  # the literal L_p <= level
        return no if level < 1 else yes if level >= stack else int(at[p, level - 1])

    def below(p: int, q: int, *unless: int) -> list[list[int]]:
        """Clauses: L_p < L_q (unless one of the literals `unless` holds)."""
        return [[*unless, -upto(q, lv), upto(p, lv - 1)] for lv in range(1, stack + 1)]

    clauses = [[-no], [yes]]
    clauses += [[-upto(p, lv), upto(p, lv + 1)] for p in range(n) for lv in range(1, stack - 1)]
    for p, q in zip(*np.nonzero(np.triu(conflict, 1))):
        clauses += [[-upto(p, lv), upto(p, lv - 1), -upto(q, lv), upto(q, lv - 1)]
                    for lv in range(1, stack + 1)]  # fmt: skip
    side = yes + 1  # a fresh literal per part kept between a pin's plates: true, below them
    for members, blocked, rule in rules:
        for b in blocked:
            if rule == "after":
                clauses += [c for m in members for c in below(m, b)]
            elif rule == "before":
                clauses += [c for m in members for c in below(b, m)]
            elif len(members) >= 2:
                clauses += [c for m in members for c in below(b, m, -side) + below(m, b, side)]
                side += 1
    with Solver(name=SOLVER, bootstrap_with=clauses) as solver:
        if not solver.solve():
            return None
        model = set(solver.get_model())
    return [1 + sum(upto(p, lv) not in model for lv in range(1, stack)) for p in range(n)]
