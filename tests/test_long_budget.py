"""A longer budget's search (linkd.design.search): the default budget's search inside it, on a
loop or a stroke, and a polish that goes on down the ranking while time remains."""

import time

import numpy as np
from test_design import QUICK, pool_proposer
from test_polish import FINE, _coarsely_refined, _unit_crank_rocker

from linkd.constraints import Constraints
from linkd.design import budget as budget_module
from linkd.design import search as search_module
from linkd.design.pipeline import DesignOptions
from linkd.design.polish import POLISH_RANGE, polish
from linkd.design.search import _refiner, search
from linkd.design.stages import Stages
from linkd.design.stroke import Goal


def _search(pool, budget: float, seconds: float, closed: bool = True) -> tuple:
    """The candidates and report of a search for a crank-rocker's curve (or, not `closed`, the
    first half of it as a stroke) with `budget`, its deadline `seconds` from now."""
    options = DesignOptions(candidates=12, time_budget=budget, refine_settings=QUICK,
                            atlas=False)  # fmt: skip
    report, deadline = {}, time.monotonic() + seconds
    target = _unit_crank_rocker() if closed else _unit_crank_rocker()[:100]
    found = search(Goal(target, closed, False), Constraints(), options, pool_proposer(pool),
                   Stages(False), deadline, report)  # fmt: skip
    return found, report


def test_a_longer_budget_holds_the_default_search(pool, monkeypatch):
    """With the same seed, a double budget's search first finds what a default run finds (the
    same best design before the polish) and then searches wider; it delivers no worse. The
    default budget is taken as 10 s (the search's widths count it, its deadlines scale with
    it): the same searches as for 30 s and 60 s, with less time waiting on the deadline."""
    for module in (budget_module, search_module):
        monkeypatch.setattr(module, "BUDGET_STEP", 10.0)
    short, short_report = _search(pool, 10, 600)
    # The default search inside ends where a default run's would: 11 s before this deadline,
    # which leaves it 31 s; it takes 15 to 22 s on a 2-core machine that gives 19,000 to
    # 26,000 mechanisms/s in `linkd bench kinematics` (with 12 s it was cut there).
    long, long_report = _search(pool, 20, 42)
    assert "default_search" not in short_report
    assert long_report["default_search"]["best"] == short_report["polish"]["before"]
    assert long_report["refined"] > short_report["refined"]
    assert np.min(long.chamfer) <= np.min(short.chamfer)


def test_a_longer_budget_holds_the_default_search_on_a_stroke_too(pool, monkeypatch):
    """A stroke has no polish, but a double budget's search holds the default run's all the
    same: the same best design, then a wider search; it delivers no worse."""
    for module in (budget_module, search_module):
        monkeypatch.setattr(module, "BUDGET_STEP", 10.0)
    short, short_report = _search(pool, 10, 600, closed=False)
    long, long_report = _search(pool, 20, 60, closed=False)
    assert "default_search" not in short_report and "polish" not in long_report
    assert long_report["default_search"]["best"] == np.min(short.chamfer)
    assert long_report["refined"] > short_report["refined"]
    assert np.min(long.chamfer) <= np.min(short.chamfer)


def _polished(candidates, target, count, until) -> dict:
    goal = Goal(target, True, False)
    refine_finely = _refiner(goal, target, False, FINE, Constraints(), deadline=np.inf)
    return polish(candidates, count, 4, refine_finely, lambda *_: None, until)


def _ranked():
    candidates, target = _coarsely_refined(copies=4)
    candidates.refined[:] = True
    return candidates, target


def test_the_polish_goes_down_the_ranking_while_time_remains():
    candidates, target = _ranked()
    assert _polished(candidates, target, 1, None)["designs"] == 1  # the best only
    candidates, target = _ranked()
    far = int(np.argmax(candidates.chamfer))
    candidates.chamfer[far] = 2.5 * candidates.chamfer.min()  # past POLISH_RANGE times the best
    assert POLISH_RANGE < 2.5
    old = candidates.batch.positions.copy()
    done = _polished(candidates, target, 1, time.monotonic() + 600)
    assert done["designs"] == 3  # one at a time, down to the one too far
    moved = np.abs(candidates.batch.positions - old).max((1, 2)) > 0
    assert moved.tolist() == [row != far for row in range(4)]
    candidates, target = _ranked()  # out of time after the first: only the best
    assert _polished(candidates, target, 1, time.monotonic())["designs"] == 1
