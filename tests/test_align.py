"""Alignment of candidate curves to a target: recovers known similarities (reflection included),
treats each candidate of a batch on its own, and beats a dense grid of rotations."""

from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from linkd.align import SimilarityBatch, align
from linkd.curves import chamfer, normalise, read_curve, resample
from linkd.geometry import Similarity, rotation

EXAMPLES = Path(__file__).parents[1] / "assets" / "examples"
CRESCENT = read_curve(EXAMPLES / "crescent.csv")
JANSEN = read_curve(EXAMPLES / "jansen_foot.csv")


def _size(points):
    return float(np.sqrt(((points - points.mean(axis=0)) ** 2).sum(axis=1).mean()))


@settings(max_examples=25, deadline=None)
@given(
    st.sampled_from([CRESCENT, JANSEN]),
    st.floats(-np.pi, np.pi),
    st.booleans(),
    st.floats(-3, 3),
    st.tuples(st.floats(-500, 500), st.floats(-500, 500)),
    st.integers(0, 199),
)
def test_recovers_a_known_similarity(curve, angle, reflect, log_scale, shift, start):
    truth = Similarity(float(np.exp(log_scale)), rotation(angle, reflect), np.array(shift))
    candidate = np.roll(resample(curve, 200), start, axis=0)
    target = truth.apply(np.roll(resample(curve, 150), 40, axis=0))  # other points, other start
    sims, distances = align(candidate[None], target)
    found = sims[0]
    assert found.reflects == reflect
    error = np.abs(found.apply(candidate) - truth.apply(candidate)).max()
    assert error < 0.01 * _size(target)
    # The fit is polished on 64 points per curve, so it lands near, not on, the optimum of the
    # Chamfer distance of all points: within 0.1% of the curve's size of the true similarity's
    # distance (measured: up to 0.026%). A bound relative to that distance is too tight: it is
    # only the gap between the two samplings (2% of the size), and 1% of it was exceeded.
    best_possible = chamfer(truth.apply(candidate), target)
    assert distances[0] <= best_possible + 0.001 * _size(target)
    assert distances[0] == pytest.approx(chamfer(found.apply(candidate), target), rel=1e-9)


def _smooth_curve(seed, n=200):
    """A random smooth closed curve: a few Fourier terms."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)[:, None]
    k = np.arange(1, 4)
    coeffs = rng.normal(size=(4, 3)) / k
    x = (coeffs[0] * np.cos(k * t) + coeffs[1] * np.sin(k * t)).sum(axis=1)
    y = (coeffs[2] * np.cos(k * t) + coeffs[3] * np.sin(k * t)).sum(axis=1)
    return np.c_[x, y]


def test_each_candidate_of_a_batch_is_aligned_on_its_own():
    candidates = np.stack([_smooth_curve(seed) for seed in range(6)])
    target = 40 * JANSEN[::2] + 7.0
    sims, distances = align(candidates, target)
    assert isinstance(sims, SimilarityBatch) and len(sims) == 6 and distances.shape == (6,)
    for k, candidate in enumerate(candidates):
        one_sims, one_distance = align(candidate[None], target)
        assert one_distance[0] == pytest.approx(distances[k], rel=1e-5)
        np.testing.assert_allclose(
            one_sims.apply(candidate[None])[0], sims.apply(candidates)[k], atol=1e-4 * _size(target)
        )
    moved = sims.apply(candidates)
    for k, sim in enumerate(sims):
        np.testing.assert_allclose(sim.apply(candidates[k]), moved[k])
        assert chamfer(moved[k], target) == pytest.approx(distances[k], rel=1e-9)
    np.testing.assert_array_equal(sims.reflects, [s.reflects for s in sims])


def _grid_best(candidate, target, angles=72):
    """Chamfer distance after the best of a grid of rotations (and reflections), with centroid
    and RMS radius matched."""
    p, _ = normalise(candidate)
    _, to_target = normalise(target)
    best = np.inf
    for reflect in (False, True):
        for angle in np.linspace(0, 2 * np.pi, angles, endpoint=False):
            moved = to_target.apply(p @ rotation(angle, reflect).T)
            best = min(best, chamfer(moved, target))
    return best


def test_never_worse_than_a_dense_grid_of_rotations():
    target = JANSEN
    candidates = np.stack([resample(CRESCENT, 200), *(_smooth_curve(s) for s in range(3))])
    _, distances = align(candidates, target)
    for candidate, distance in zip(candidates, distances):
        assert distance <= _grid_best(candidate, target)


def test_reflection_can_be_ruled_out():
    mirrored = CRESCENT * [1.0, -1.0]
    candidate = resample(CRESCENT, 200)[None]
    with_reflection, d_with = align(candidate, mirrored)
    without, d_without = align(candidate, mirrored, reflect=False)
    assert with_reflection.reflects[0] and not without.reflects[0]
    assert d_with[0] <= 1.01 * chamfer(candidate[0] * [1.0, -1.0], mirrored)
    assert d_without[0] > 2 * d_with[0]


def test_accepts_torch_and_numpy_and_flags_broken_candidates():
    candidates = np.stack([_smooth_curve(1), _smooth_curve(2), np.full((200, 2), np.nan)])
    target = resample(CRESCENT, 120)
    _, distances = align(candidates, target)
    assert np.isfinite(distances[:2]).all() and distances[2] == np.inf
    _, from_torch = align(torch.tensor(candidates, dtype=torch.float32), torch.tensor(target))
    np.testing.assert_allclose(from_torch[:2], distances[:2], rtol=1e-4)
    point = align(np.ones((1, 50, 2)), target)[1]  # a candidate that does not move
    assert np.isfinite(point).all()
    empty_sims, empty = align(np.zeros((0, 50, 2)), target)
    assert len(empty_sims) == 0 and empty.shape == (0,)


def test_identical_curves_align_exactly():
    sims, distances = align(CRESCENT[None], CRESCENT)
    assert distances[0] == pytest.approx(0.0, abs=1e-9 * _size(CRESCENT))
    np.testing.assert_allclose(sims.apply(CRESCENT[None])[0], CRESCENT, atol=1e-4)
