"""The layer searches' exact answers (`export.exact`) against brute force on small stacks."""

from itertools import permutations, product

import numpy as np
import pytest

from linkd.export import stacking
from linkd.export.stacking import PinState, fewest_layers, find_order, stack_in_order


def _stacks(count: int, seed: int = 0):
    """Random small stacking problems as the export poses them: pins of moving parts, pins in
    the base and from the cover, and each part kept off a pin conflicting with its plates."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        n = int(rng.integers(2, 7))
        pins = []
        for _ in range(rng.integers(1, 6)):
            members = rng.choice(n, size=rng.integers(0, min(3, n) + 1), replace=False).tolist()
            pins.append((members, [q for q in range(n) if q not in members and rng.random() < 0.3]))
        grounded = {k for k in range(len(pins)) if rng.random() < 0.3}
        cover = {k for k in grounded if rng.random() < 0.5}
        conflict = np.triu(rng.random((n, n)) < 0.3, 1)
        for members, blocked in pins:
            conflict[np.ix_(members, blocked)] = True
        conflict = conflict | conflict.T
        np.fill_diagonal(conflict, False)
        yield n, pins, grounded, cover, conflict


def _placeable(order, n, pins, grounded, cover) -> bool:
    """Can the parts be placed bottom up in `order`, every pin kept clear?"""
    state = PinState(n, pins, grounded, cover)
    for p in order:
        if not state.free(p):
            return False
        state.place(p, 1)
    return True


@pytest.mark.parametrize("budget", [stacking.SEARCH_BUDGET, 0])
def test_an_order_is_found_wherever_one_exists(monkeypatch, budget):
    """With no budget at all for the depth-first search, the solver's order is taken."""
    monkeypatch.setattr(stacking, "SEARCH_BUDGET", budget)
    found = 0
    for n, pins, grounded, cover, conflict in _stacks(300):
        order = find_order(PinState(n, pins, grounded, cover), conflict)
        exists = any(_placeable(p, n, pins, grounded, cover) for p in permutations(range(n)))
        assert (order is not None) == exists
        if order is not None:
            assert sorted(order) == list(range(n)) and _placeable(order, n, pins, grounded, cover)
            found += 1
    assert 50 < found < 300  # both answers are met


def test_the_fewest_layers_are_found():
    """Brute force over every assignment of layers: parts that conflict apart, each part kept
    off a pin below or above all its plates (under all of them for a pin from the cover, over
    them for one in the base)."""

    def keeps(layers, n, pins, grounded, cover, conflict) -> bool:
        apart = all(layers[p] != layers[q] for p, q in zip(*np.nonzero(conflict)))
        order = sorted(range(n), key=lambda p: layers[p])
        return apart and _placeable(order, n, pins, grounded, cover)

    for n, pins, grounded, cover, conflict in _stacks(200, seed=1):
        if n > 5:
            continue
        order = find_order(PinState(n, pins, grounded, cover), conflict)
        if order is None:
            continue
        layers = fewest_layers(conflict, PinState(n, pins, grounded, cover),
                               stack_in_order(conflict, order))  # fmt: skip
        assert keeps(layers, n, pins, grounded, cover, conflict)
        fewer = product(range(max(layers) - 1), repeat=n)
        assert not any(keeps(c, n, pins, grounded, cover, conflict) for c in fewer)
