"""Delivery passes over designs the export refuses, quickly once a few have been refused
(linkd.design.pipeline._deliver)."""

import numpy as np
import pytest
from test_export_narrow import STUBBORN, TANGLED

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.design import pipeline
from linkd.design.output import PassedOver, keep_passed_over, skip_counts
from linkd.design.pipeline import DesignOptions, NoDesign, _ranked
from linkd.design.propose import Candidates
from linkd.design.select import end_effector_path, measure
from linkd.design.stages import Stages
from linkd.geometry import Similarity
from linkd.mechanism import Mechanism

ROCKER = classic.crank_rocker()


def _delivered(mechanisms, folder, passed=None, **options):
    """The design delivered from `mechanisms`, ranked in that order (not reordered by their
    errors on the crank rocker's path, the target here: these tests follow delivery down a
    ranking), and how many were passed over, by reason (each listed in `passed`)."""
    batch = LinkageBatch.from_mechanisms(mechanisms)
    candidates = Candidates(batch, np.arange(len(mechanisms)) * 0.1)
    passed = [] if passed is None else passed
    points = end_effector_path(ROCKER)[0]
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(pipeline, "_simplest_first", lambda order, *_: order)
        found, _, _ = pipeline._deliver(candidates, Similarity(), points,
                                        DesignOptions(formats=frozenset({"mjcf"}), **options),
                                        Stages(False), folder, {}, passed, np.inf)  # fmt: skip
    return found.mechanism, skip_counts(passed)


def _same(mech, other) -> bool:
    """Whether two mechanisms have their joints at the same places (in any order)."""
    a, b = (np.unique(m.positions.round(6), axis=0) for m in (mech, other))
    return a.shape == b.shape and np.allclose(a, b)


def test_after_a_refusal_designs_are_checked_quickly_before_a_try(tmp_path, monkeypatch):
    monkeypatch.setattr(pipeline, "QUICK_AFTER", 1)
    monkeypatch.setattr(pipeline, "FAILURES_PER_TOPOLOGY", 3)
    # STUBBORN is refused by the export; then the quick check refuses it twice more, and
    # TANGLED (which only narrower links build), without a try.
    found, skipped = _delivered([STUBBORN] * 3 + [TANGLED, ROCKER], tmp_path)
    assert _same(found, ROCKER) and skipped["unbuildable"] == 4


def test_without_the_quick_checks_the_slower_constructions_are_tried(tmp_path, monkeypatch):
    monkeypatch.setattr(pipeline, "QUICK_AFTER", 10)
    passed = []
    found, skipped = _delivered([STUBBORN, TANGLED, ROCKER], tmp_path, passed)
    assert _same(found, TANGLED) and skipped["unbuildable"] == 1
    # what was given up is in plain view: the refused design and its curve error
    error = measure(STUBBORN, end_effector_path(ROCKER)[0]).chamfer
    assert [p.to_dict() for p in passed] == [
        {"reason": "unbuildable", "chamfer": pytest.approx(error), "why": passed[0].why}
    ]
    assert passed[0].why.startswith("cannot be built from flat layers")
    # and kept, with its figures and why, for the designer to build otherwise or to move
    entry = keep_passed_over(passed[0], tmp_path)
    kept = Mechanism.load(tmp_path / entry["folder"] / "mechanism.json")
    assert _same(kept, STUBBORN) and kept.links == STUBBORN.links
    assert kept.extra["passed_over"]["reason"] == "unbuildable"
    assert kept.extra["metrics"]["chamfer"] == pytest.approx(error)


def test_a_design_passed_over_unmeasured_is_not_kept(tmp_path):
    entry = keep_passed_over(PassedOver("invalid"), tmp_path)
    assert entry == {"reason": "invalid"} and not list(tmp_path.iterdir())


def test_delivery_gives_up_after_its_quick_checks(tmp_path, monkeypatch):
    monkeypatch.setattr(pipeline, "QUICK_AFTER", 0)
    monkeypatch.setattr(pipeline, "QUICK_CHECKS", 2)
    with pytest.raises(NoDesign, match="2 more checked could not be built"):
        _delivered([STUBBORN, TANGLED, ROCKER], tmp_path)


def test_after_half_the_attempts_only_designs_the_rounds_did_not_grow_are_tried():
    order = np.array([3, 0, 4, 1, 2])  # best first
    grown = np.array([False, True, False, True, True])
    given = []
    for row in _ranked(order, grown, lambda: len(given) >= 2):
        given.append(row)
    assert given == [3, 0, 2]  # then the best not grown (0 was given already)


def test_of_designs_that_trace_the_curve_alike_the_simplest_goes_first(monkeypatch):
    """A six-bar on the curve, ranked first, and the five-joint crank rocker off it: where the
    difference of their errors is within what counts as alike, the crank rocker is tried
    first; where it is not, the six-bar."""
    six = classic.stephenson_six_bar()
    points = end_effector_path(six)[0]
    candidates = Candidates(LinkageBatch.from_mechanisms([six, ROCKER]), np.array([0.1, 0.2]))
    errors = [measure(m, points).chamfer for m in (six, ROCKER)]
    assert errors[0] < errors[1] and six.n_nodes > ROCKER.n_nodes

    def first(floor: float) -> int:
        monkeypatch.setattr(pipeline, "SIMPLER_FLOOR", floor)
        order = pipeline._simplest_first(np.array([0, 1]), candidates, Similarity(), points,
                                         DesignOptions())  # fmt: skip
        return int(order[0])

    difference = errors[1] - errors[0]
    assert first(1.01 * difference) == 1 and first(0.99 * difference) == 0


def test_a_smaller_design_ranked_near_the_best_is_weighed_beyond_the_pool(monkeypatch):
    """With room in the pool for the six-bar alone, the crank rocker behind it is still weighed
    (and goes first, the two alike) while it is ranked near the best, and not when it is far."""
    six = classic.stephenson_six_bar()
    points = end_effector_path(six)[0]
    monkeypatch.setattr(pipeline, "SIMPLER_POOL", 1)
    monkeypatch.setattr(pipeline, "SIMPLER_FLOOR", 10.0)  # any two designs are alike

    def order(ranked: list[float]) -> list[int]:
        candidates = Candidates(LinkageBatch.from_mechanisms([six, ROCKER]), np.array(ranked))
        return pipeline._simplest_first(np.array([0, 1]), candidates, Similarity(), points,
                                        DesignOptions()).tolist()  # fmt: skip

    assert order([0.1, 0.11]) == [1, 0]
    assert order([0.1, 30.0]) == [0, 1]
