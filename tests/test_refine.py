"""Refinement: batched L-BFGS, the curve losses, and pulling perturbed mechanisms back on curve."""

import numpy as np
import pytest
import torch

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.curves import chamfer, normalise, ordered_distance_batch, resample
from linkd.design.lbfgs import minimise
from linkd.design.refine import (
    KD_PAIRS,
    RefineSettings,
    nearest_vertices,
    ordered_distance,
    polyline_chamfer,
    refine,
    resample_closed,
)
from linkd.design.select import end_effector_path, to_mechanism
from linkd.geometry import Similarity
from linkd.validator import validate_mechanism


def ellipse(n: int, unevenness: float = 0.0) -> np.ndarray:
    """A closed egg-like curve at n parameter values, evenly spaced or (unevenness in [0, 1))
    bunched up."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    t = t + unevenness * np.sin(t)
    return np.stack([2 * np.cos(t), np.sin(t) + 0.3 * np.sin(2 * t)], 1)


def test_lbfgs_solves_independent_ill_conditioned_problems():
    # Row b minimises sum_i c_bi (x_i - 1)^2 with conditioning up to 1e4; one row is NaN.
    scales = torch.tensor([[1.0, 10.0, 100.0, 1e4], [1.0, 1.0, 1.0, 1.0], [5.0, 1.0, 3.0, 2.0]])

    def evaluate(x, rows):
        c = scales[rows]
        f = (c * (x - 1) ** 2).sum(1)
        f = torch.where(rows == 1, torch.nan, f)
        return f, 2 * c * (x - 1)

    calls = []

    def counted(x, rows):
        calls.append(len(rows))
        return evaluate(x, rows)

    x0 = torch.zeros(3, 4, dtype=torch.float64)
    x, iterations = minimise(counted, x0, 200, first_step=0.1)
    assert torch.allclose(x[0], torch.ones(4, dtype=torch.float64), atol=1e-6)
    assert torch.allclose(x[2], torch.ones(4, dtype=torch.float64), atol=1e-6)
    assert torch.equal(x[1], x0[1])  # never moved onto a non-finite value
    # It stops once every row has converged, and says it did all it was asked (fewer would
    # mean a deadline cut it short).
    assert len(calls) < 100 and iterations == 200


def test_lbfgs_rows_do_not_wait_for_each_others_line_searches():
    # Row 0 is an ill-conditioned bowl; row 1 is |x| next to its kink, where trials fail.
    scales = torch.tensor([1.0, 10.0, 100.0], dtype=torch.float64)

    def evaluate(x, rows):
        bowl = (scales * (x - 1) ** 2).sum(1), 2 * scales * (x - 1)
        kink = x.abs().sum(1), torch.sign(x)
        smooth = (rows == 0)[:, None]
        return torch.where(smooth[:, 0], bowl[0], kink[0]), torch.where(smooth, bowl[1], kink[1])

    def counted(calls):
        def evaluated(x, rows):
            calls.append(rows.clone())
            return evaluate(x, rows)

        return evaluated

    alone_calls, calls = [], []
    alone, _ = minimise(counted(alone_calls), torch.zeros(1, 3, dtype=torch.float64), 200)
    start = torch.tensor([[0.0, 0.0, 0.0], [0.004, 0.004, 0.004]], dtype=torch.float64)
    x, _ = minimise(counted(calls), start, 200)
    assert torch.allclose(alone[0], torch.ones(3, dtype=torch.float64), atol=1e-6)
    assert torch.equal(x[0], alone[0])
    # As fast as alone, beside a row that backtracks: evaluated as often, once an iteration.
    assert sum(bool((rows == 0).any()) for rows in calls) == len(alone_calls) < 200


def test_polyline_chamfer_ignores_sampling_density():
    target = torch.as_tensor(resample(ellipse(1000), 200))  # the target is evenly resampled
    # The same curve, traced with a very uneven speed: the distance stays near zero.
    uneven = torch.as_tensor(ellipse(300, unevenness=0.8))
    assert polyline_chamfer(uneven[None], target).item() < 1e-3
    moved = torch.as_tensor(ellipse(300) + np.array([0.05, 0.0]))[None]
    dense = chamfer(resample(moved[0].numpy(), 4000), resample(target.numpy(), 4000))
    assert polyline_chamfer(moved, target).item() == pytest.approx(dense, rel=0.02)


@pytest.mark.parametrize("points", [(64, 100), (1024, 2000)])  # all pairs at once; k-d trees
def test_nearest_vertices_are_the_nearest_both_ways(points):
    t, m = points
    assert (t * m < KD_PAIRS) == (points == (64, 100))
    rng = np.random.default_rng(0)
    paths = torch.as_tensor(np.stack([ellipse(t) * rng.uniform(0.5, 2) + rng.normal(0, 0.5, 2)
                                      for _ in range(3)]))  # fmt: skip
    paths[1, 5] = torch.nan  # a locked pose: its distances stay NaN, the others are unaffected
    target = torch.as_tensor(ellipse(m) + rng.normal(0, 0.01, (m, 2)))
    near_target, near_path = nearest_vertices(paths, target)
    d = torch.cdist(paths, target[None].expand(3, -1, -1))  # (3, T, M)
    finite = torch.isfinite(paths).all(-1)
    picked = d.gather(2, near_target[..., None])[..., 0]
    assert torch.allclose(picked[finite], d.amin(2)[finite])
    clean = [0, 2]
    picked = d[clean].gather(1, near_path[clean][:, None])[:, 0]
    assert torch.allclose(picked, d[clean].amin(1))
    assert near_path.min() >= 0 and near_path.max() < t


def test_ordered_distance_finds_shift_and_direction():
    target = torch.as_tensor(ellipse(200))
    turned = torch.roll(target.flip(0), 37, 0)[None]
    assert ordered_distance(turned, target).item() < 1e-5
    noisy = turned + 0.01 * torch.randn(turned.shape, generator=torch.Generator().manual_seed(0))
    expected = ordered_distance_batch(noisy, target).item()
    assert ordered_distance(noisy, target).item() == pytest.approx(expected, rel=1e-6)
    # Arc-length resampling keeps every point on the polyline and spaces them evenly.
    even = resample_closed(torch.as_tensor(ellipse(400))[None], 100)[0].numpy()
    steps = np.linalg.norm(np.diff(np.vstack([even, even[:1]]), axis=0), axis=1)
    assert steps.std() / steps.mean() < 0.02


def _perturbed(mech, copies: int, noise: float, seed: int = 0):
    """A batch of noisy copies of `mech` in the normalised frame of its own path, the target
    path, and the frame."""
    path = end_effector_path(mech, 1000)[0]
    target, frame = normalise(resample(path, 200))
    exact = mech.transformed(frame.inverse())
    batch = LinkageBatch.from_mechanisms([exact] * copies)
    size = exact.scale
    rng = np.random.default_rng(seed)
    batch.positions = batch.positions + rng.normal(0, noise * size, batch.positions.shape)
    return batch, target, frame


@pytest.mark.parametrize("make", [classic.crank_rocker, classic.stephenson_six_bar])
def test_refinement_pulls_perturbed_mechanisms_back_onto_their_curve(make):
    batch, target, frame = _perturbed(make(), copies=4, noise=0.02)
    before = refine(batch, target, RefineSettings(iterations=0)).chamfer
    result = refine(batch, target, RefineSettings(iterations=80))
    assert result.ok.all()
    assert np.all(result.chamfer < 0.01) and np.all(result.chamfer < 0.2 * before)
    batch.positions = result.positions
    for row in range(len(batch)):
        mech = to_mechanism(batch, row, frame, "mm")
        status, margin = validate_mechanism(mech)
        assert status == 0 and margin >= RefineSettings().min_margin * 0.9
        path = end_effector_path(mech, 1000)[0]
        user_target = frame.apply(target)
        error = chamfer(resample(path, 2000), resample(user_target, 2000)) / frame.scale
        assert error < 0.015


def test_refinement_keeps_the_input_when_it_cannot_improve_validly():
    # A locked start (the non-Grashof four-bar cannot turn) is never reported as valid.
    mech = classic.non_grashof_four_bar()
    batch = LinkageBatch.from_mechanisms([mech])
    target = normalise(resample(ellipse(200), 200))[0]
    frame = Similarity()
    result = refine(batch, target, RefineSettings(iterations=0))
    assert not result.ok[0] and np.isinf(result.chamfer[0])
    np.testing.assert_array_equal(result.positions, batch.positions)
    assert to_mechanism(batch, 0, frame, "mm").n_nodes == mech.n_nodes


def test_the_error_reported_is_the_finely_traced_one_whatever_the_early_iterations_used():
    batch, target, _ = _perturbed(classic.crank_rocker(), copies=3, noise=0.03)
    coarse = RefineSettings(iterations=20, ordered_iterations=20, ordered_angles=16)
    result = refine(batch, target, coarse)
    assert result.ok.all()
    batch.positions = result.positions
    measured = refine(batch, target, RefineSettings(iterations=0)).chamfer
    np.testing.assert_allclose(result.chamfer, measured, rtol=1e-5)


def _peak_acceleration(batch: LinkageBatch, positions: np.ndarray) -> np.ndarray:
    """(B,) every design's largest joint acceleration per unit crank speed squared."""
    from linkd.verify.analytic import joint_paths

    peaks = []
    for row in range(len(batch)):
        moved = batch.subset([row])
        moved.positions = positions[row : row + 1]
        paths = joint_paths(to_mechanism(moved, 0, Similarity(), "mm"), 512)
        second = np.roll(paths, 1, 1) - 2 * paths + np.roll(paths, -1, 1)
        peaks.append(np.linalg.norm(second, axis=-1).max() * (512 / (2 * np.pi)) ** 2)
    return np.array(peaks)


def test_refinement_keeps_joint_accelerations_under_the_limit():
    """Refined towards a curve that asks for sharp turns, designs trade a little accuracy for
    joints that do not jerk: with a limit under what the free refinement reaches, every peak
    acceleration ends lower, and not far past the limit."""
    batch, target, _ = _perturbed(classic.stephenson_six_bar(), copies=4, noise=0.05)
    free = refine(batch, target, RefineSettings(iterations=60, soft_acceleration=0.0))
    reached = _peak_acceleration(batch, free.positions)
    limit = 0.5 * reached.min()
    held = refine(batch, target, RefineSettings(iterations=60, soft_acceleration=limit))
    assert free.ok.all() and held.ok.all()
    peaks = _peak_acceleration(batch, held.positions)
    assert np.all(peaks < reached) and np.all(peaks < 1.5 * limit)
