"""Stacking parts into layers: a pin-safe order, then the fewest layers.

The parts are placed bottom up. Pairwise conflicts keep two parts off one layer; a pin keeps
the parts that come near it out of the layers between its outermost plates. Whether an order
exists, and how few layers will do, are settled exactly (`exact`); a budgeted depth-first
search finds the order itself, where it can, since its orders stack compactly.
"""

from __future__ import annotations

import numpy as np

from .exact import exact_order, exact_stack

SEARCH_BUDGET = 5_000  # dead ends the depth-first search meets before the solver's order is taken


class PinState:
    """The pins as parts are placed bottom up, in any grouping into layers.

    A pin is open from when the first of its plates is placed until the last one is; a part
    that comes near it cannot be placed while it is open (it would sit between the pin's
    plates; a part on the layer of one of them conflicts with it anyway). A pin standing in the
    base is open from the start; one hanging from the cover never closes. `rules` says the same
    for the exact searches: each pin as (its plates, the parts kept off it, "between", "after"
    (in the base) or "before" (from the cover)).
    """

    def __init__(self, n: int, pins: list, grounded: set[int], cover: set[int]):
        self.member_of = [[k for k, (m, _) in enumerate(pins) if p in m] for p in range(n)]
        self.blocked = [b for _, b in pins]
        self.total = [len(m) + (k in grounded) for k, (m, _) in enumerate(pins)]
        self.placed = [int(k in grounded and k not in cover) for k in range(len(pins))]
        self.blocking = [0] * n  # open pins each part waits for
        for k in range(len(pins)):
            if self.is_open(k):
                for b in self.blocked[k]:
                    self.blocking[b] += 1
        self.layer = [0] * n  # 0: not placed yet
        self.left = n
        self.rules = [
            ([p for p in range(n) if p in members], [b for b in blocked if b not in members],
             "between" if k not in grounded else "before" if k in cover else "after")
            for k, (members, blocked) in enumerate(pins)
        ]  # fmt: skip

    def is_open(self, pin: int) -> bool:
        return 0 < self.placed[pin] < self.total[pin]

    def free(self, p: int) -> bool:
        return not self.layer[p] and not self.blocking[p]

    def ready(self) -> list[int]:
        """The parts that can be placed next."""
        layer, blocking = self.layer, self.blocking
        return [p for p in range(len(layer)) if not layer[p] and not blocking[p]]

    def place(self, p: int, level: int, step: int = 1) -> None:
        """Place part p on `level` (step 1) or take it back (step -1). The hottest loop of the
        layer searches: the pins' counts are read once each."""
        self.layer[p] = level if step > 0 else 0
        self.left -= step
        placed, total, blocking = self.placed, self.total, self.blocking
        for k in self.member_of[p]:
            before = placed[k]
            placed[k] = after = before + step
            was, now = 0 < before < total[k], 0 < after < total[k]
            if was != now:
                for b in self.blocked[k]:
                    blocking[b] += 1 if now else -1

    def closes(self, p: int) -> int:
        """How many open pins placing p would close, less how many it would open."""
        score = 0
        placed, total = self.placed, self.total
        for k in self.member_of[p]:
            done, needed = placed[k], total[k]
            if 0 < done == needed - 1:
                score += 1
            elif done == 0 and needed > 1 and self.blocked[k]:
                score -= 1
        return score


def find_order(state: PinState, conflict: np.ndarray) -> list[int] | None:
    """An order in which every part of a fresh `state` can be placed bottom up, or None: there
    is none. A SAT solver settles whether one exists (`exact`); where one does, a depth-first
    search looks for it, since its orders stack compactly, and the solver's is taken where
    that search gives up within its budget."""
    exact = exact_order(len(state.layer), state.rules)
    if exact is None:
        return None
    return _depth_first(state, conflict) or exact


def _depth_first(state: PinState, conflict: np.ndarray) -> list[int] | None:
    """An order in which every part can be placed bottom up, or None within the budget.

    Preferring parts that fit on the layer being filled (see `stack_in_order`), then parts
    that close pins rather than open them. Which pins are open depends only on the set of parts
    placed, so a set that led nowhere is never expanded again.
    """
    clashes = [sum(1 << q for q in np.flatnonzero(row)) for row in conflict]  # as bit sets
    dead: set[int] = set()
    order: list[int] = []

    def extend(placed: int, here: int) -> bool:
        if state.left == 0:
            return True
        if placed in dead or len(dead) > SEARCH_BUDGET:
            return False
        ready = [p for p in state.ready() if placed | 1 << p not in dead]  # dead: not entered
        for p in sorted(ready, key=lambda p: (bool(clashes[p] & here), -state.closes(p))):
            fits = not clashes[p] & here
            state.place(p, len(order) + 1)
            order.append(p)
            if extend(placed | 1 << p, here | 1 << p if fits else 1 << p):
                return True
            order.pop()
            state.place(p, 0, -1)
        dead.add(placed)
        return False

    return order if extend(0, 0) else None


def stack_in_order(conflict: np.ndarray, order: list[int]) -> list[int]:
    """Layers for parts placed in a valid order: each joins the current layer unless it
    conflicts with a part there (then it opens the next one). The order keeps pins clear."""
    layers = [0] * len(order)
    level, here = 1, []
    for p in order:
        if conflict[p, here].any():
            level, here = level + 1, []
        layers[p] = level
        here.append(p)
    return layers


def fewest_layers(conflict: np.ndarray, state: PinState, layers: list[int]) -> list[int]:
    """The fewest layers that keep every pin of `state` clear (its `rules`: the search for an
    order leaves them as they were), fewer than `layers` if any (`exact.exact_stack`, from a
    clique's size up: no fewer can work)."""
    for stack in range(_clique(conflict), max(layers, default=0)):
        found = exact_stack(conflict, state.rules, stack)
        if found is not None:
            return found
    return layers


def _clique(conflict: np.ndarray) -> int:
    """Size of a clique found greedily: fewer layers than that cannot work."""
    degree = conflict.sum(1)
    best = 1
    for v in range(len(conflict)):
        clique = [v]
        for u in sorted(np.flatnonzero(conflict[v]), key=lambda u: -degree[u]):
            if conflict[u, clique].all():
                clique.append(u)
        best = max(best, len(clique))
    return best
