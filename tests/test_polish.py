"""The last refinement of the best designs, at finer crank angles (linkd.design.polish)."""

import time
from dataclasses import replace

import numpy as np
import pytest
from test_design import QUICK, pool_proposer
from test_refine import _perturbed

from linkd import classic
from linkd.constraints import Constraints
from linkd.design.pipeline import DesignOptions
from linkd.design.polish import polish
from linkd.design.propose import Candidates
from linkd.design.refine import RefineSettings, refine
from linkd.design.search import POLISH_SHARE, _refiner, search
from linkd.design.select import curve_error, end_effector_path, to_mechanism
from linkd.design.stages import Stages
from linkd.design.stroke import Goal
from linkd.geometry import Similarity

FINE = RefineSettings(angles=1024, iterations=60, ordered_iterations=0, ordered_weights=(0.0,))


def _coarsely_refined(copies: int = 3):
    """Candidates refined against their own four-bar's curve with the path traced at only 24
    crank angles, whose polyline cuts the curve's corners; and the target."""
    batch, target, _ = _perturbed(classic.crank_rocker(), copies=copies, noise=0.05)
    coarse = RefineSettings(iterations=60, ordered_iterations=20, angles=24, ordered_angles=24)
    result = refine(batch, target, coarse)
    assert result.ok.all()
    batch.positions = result.positions
    return Candidates(batch, result.chamfer.copy()), target


def _errors(candidates: Candidates, target: np.ndarray) -> np.ndarray:
    """The curve error of each candidate as delivery measures it (2000 points)."""
    mechs = [to_mechanism(candidates.batch, row, Similarity(), "mm")
             for row in range(len(candidates))]  # fmt: skip
    return np.array([curve_error(end_effector_path(m)[0], target) for m in mechs])


def _polished(candidates, target, settings, count=3, per_topology=3) -> dict:
    settings = replace(settings, keep=count)
    goal = Goal(target, True, False)
    refine_finely = _refiner(goal, target, False, settings, Constraints(), deadline=np.inf)
    return polish(candidates, count, per_topology, refine_finely, lambda *_: None)


def test_finer_angles_take_designs_on_from_where_coarse_ones_settled():
    candidates, target = _coarsely_refined()
    batch = candidates.batch
    finely_before = refine(batch, target, replace(FINE, iterations=0)).chamfer
    before = _errors(candidates, target)
    done = _polished(candidates, target, FINE)
    assert done["designs"] == 3 and done["after"] < done["before"]
    # The error kept is the finely traced one, and it falls well below where the coarse
    # refinement left it; delivery's 2000-point measure falls too.
    np.testing.assert_allclose(candidates.chamfer,
                               refine(batch, target, replace(FINE, iterations=0)).chamfer,
                               rtol=1e-5)  # fmt: skip
    assert np.all(candidates.chamfer < 0.5 * finely_before)
    assert np.all(_errors(candidates, target) < before)


def test_only_the_best_of_each_topology_are_polished():
    candidates, target = _coarsely_refined(copies=4)
    best = int(np.argmin(candidates.chamfer))
    old = candidates.batch.positions.copy()
    done = _polished(candidates, target, FINE, count=2, per_topology=1)
    assert done["designs"] == 1  # four copies of one topology
    moved = np.abs(candidates.batch.positions - old).max((1, 2)) > 0
    assert moved.tolist() == [row == best for row in range(4)]


def test_a_design_outside_the_hard_limits_at_finer_angles_keeps_its_place():
    candidates, target = _coarsely_refined()
    old, errors = candidates.batch.positions.copy(), candidates.chamfer.copy()
    impossible = replace(FINE, min_margin=0.99)  # no transmission angle is that good
    done = _polished(candidates, target, impossible)
    assert done["designs"] == 3 and done["after"] == done["before"]
    np.testing.assert_array_equal(candidates.batch.positions, old)
    np.testing.assert_array_equal(candidates.chamfer, errors)


def _unit_crank_rocker() -> np.ndarray:
    """A crank-rocker's coupler curve, 200 points, centred and scaled to unit RMS radius."""
    target = end_effector_path(classic.crank_rocker(), 200)[0]
    return (target - target.mean(0)) / np.sqrt(((target - target.mean(0)) ** 2).sum(1).mean())


def test_the_rounds_leave_the_last_share_of_the_budget_to_the_polish(pool):
    """A long budget's rounds would run to the deadline; a search already within the polish's
    share of its budget skips them (and the first refinement) and still polishes."""
    target = _unit_crank_rocker()
    options = DesignOptions(candidates=12, time_budget=60, refine_settings=QUICK, atlas=False,
                            rounds=3)  # fmt: skip
    stages, report = Stages(False), {}
    deadline = time.monotonic() + 0.5 * POLISH_SHARE * options.time_budget
    search(Goal(target, True, False), Constraints(), options, pool_proposer(pool), stages,
           deadline, report)  # fmt: skip
    assert report["refine_iterations"] == 0 and "round" not in stages.seconds
    assert report["polish"]["designs"] > 0
    assert time.monotonic() < deadline + 2.0  # the polish stops at the deadline


def test_a_drawn_loop_is_polished_against_its_finely_read_curve(pool):
    """The polish measures a drawn loop against `Goal.fine` (its user's points read at more
    points), the rest of the search against the 200-point target: with the fine curve moved
    aside, the polished designs' errors are those against it."""
    target = _unit_crank_rocker()
    aside = target + np.array([0.3, 0.0])
    options = DesignOptions(candidates=12, refine_settings=QUICK, atlas=False, rounds=1)
    report = {}
    found = search(Goal(target, True, False, fine=aside), Constraints(), options,
                   pool_proposer(pool), Stages(False), time.monotonic() + 60, report)  # fmt: skip
    assert report["polish"]["designs"] > 0
    best = found.batch.subset([int(np.argmin(found.chamfer))])
    finely = replace(FINE, iterations=0, ordered_iterations=0)
    assert np.min(found.chamfer) == pytest.approx(refine(best, aside, finely).chamfer[0], rel=1e-4)
    assert refine(best, target, finely).chamfer[0] > np.min(found.chamfer) + 0.05
