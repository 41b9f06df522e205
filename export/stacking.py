"""Searches that stack parts into layers: plain colouring, a pin-safe order, fewest layers.

The parts are placed bottom up. Pairwise conflicts keep two parts off one layer; a pin keeps
the parts that come near it out of the layers between its outermost plates. Budgets bound the
depth-first searches (in nodes), so an answer always comes quickly, proved or not.
"""

from __future__ import annotations

import numpy as np

SEARCH_BUDGET = 5_000  # search nodes (or dead ends) per try before settling for more layers


class PinState:
    """The pins as parts are placed bottom up, in any grouping into layers.

    A pin is open from when the first of its plates is placed until the last one is; a part
    that comes near it cannot be placed while it is open (it would sit between the pin's
    plates; a part on the layer of one of them conflicts with it anyway). A pin standing in the
    base is open from the start; one hanging from the cover never closes.
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


def find_order(state: PinState, conflict: np.ndarray) -> tuple[list[int] | None, bool]:
    """An order in which every part can be placed bottom up (or None), and whether the answer
    is proved (the search finished within its budget).

    Depth first, preferring parts that fit on the layer being filled (see `stack_in_order`),
    then parts that close pins rather than open them. Which pins are open depends only on the
    set of parts placed, so a set that led nowhere is never expanded again.
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

    found = extend(0, 0)
    return (order if found else None), found or len(dead) <= SEARCH_BUDGET


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


def chromatic_number(conflict: np.ndarray) -> tuple[int, bool]:
    """Fewest colours of a graph (the layers that pins aside would need), and whether proved."""
    neighbours = [np.flatnonzero(row).tolist() for row in conflict]
    proved = True
    for count in range(_clique(conflict), len(conflict) + 1):
        found, done = _colourable(neighbours, count)
        if found:
            return count, proved
        proved &= done
    return max(len(conflict), 1), proved


def _colourable(neighbours: list[list[int]], count: int) -> tuple[bool, bool]:
    """Can the graph take `count` colours? (answer, whether proved within the budget)

    Depth first, most constrained vertex first (DSatur order); a new colour is only ever the
    next unused one, since colours are interchangeable.
    """
    n = len(neighbours)
    colour = [-1] * n
    nodes = 0

    def free(p: int) -> list[int]:
        used = {colour[q] for q in neighbours[p]}
        return [c for c in range(count) if c not in used]

    def colour_rest(left: int) -> bool:
        nonlocal nodes
        nodes += 1
        if left == 0 or nodes > SEARCH_BUDGET:
            return left == 0
        p = min((q for q in range(n) if colour[q] < 0),
                key=lambda q: (len(free(q)), -len(neighbours[q])))  # fmt: skip
        for c in free(p):
            if c > max(colour) + 1:
                break
            colour[p] = c
            if colour_rest(left - 1):
                return True
        colour[p] = -1
        return False

    found = colour_rest(n)
    return found, found or nodes <= SEARCH_BUDGET


def _clique(conflict: np.ndarray) -> int:
    """Size of a clique found greedily: fewer colours than that cannot work."""
    degree = conflict.sum(1)
    best = 1
    for v in range(len(conflict)):
        clique = [v]
        for u in sorted(np.flatnonzero(conflict[v]), key=lambda u: -degree[u]):
            if conflict[u, clique].all():
                clique.append(u)
        best = max(best, len(clique))
    return best


class StackSearch:
    """Build a stack of `stack` layers bottom up, layer by layer, depth first.

    Within a layer, parts are added in a fixed order (most conflicts first), so every stack is
    met once; a layer is closed when nothing more fits, or to try the other choices.
    """

    def __init__(self, conflict: np.ndarray, state: PinState):
        self.neighbours = [np.flatnonzero(row).tolist() for row in conflict]
        self.order = sorted(range(len(conflict)), key=lambda p: (-len(self.neighbours[p]), p))
        self.state = state
        self.nodes = 0

    def run(self, stack: int) -> list[int] | None:
        """Layers 1..stack of the parts, or None (`nodes` tells whether that is proved)."""
        self.stack = stack
        return list(self.state.layer) if self._fill(1, -1) else None

    def _fill(self, level: int, last: int) -> bool:
        """Add to layer `level` a part after position `last` of the order, or close the layer."""
        state = self.state
        self.nodes += 1
        if state.left == 0 or self.nodes > SEARCH_BUDGET:
            return state.left == 0
        for i in range(last + 1, len(self.order)):
            p = self.order[i]
            if not state.free(p) or any(state.layer[q] == level for q in self.neighbours[p]):
                continue
            state.place(p, level)
            if self._fill(level, i):
                return True
            state.place(p, level, -1)
        return last >= 0 and level < self.stack and self._fill(level + 1, -1)
