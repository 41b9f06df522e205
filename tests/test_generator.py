"""Random curated mechanisms: valid, the requested sizes, genuine coupler curves, reproducible."""

import numpy as np
import pytest

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.generator import GeneratorSettings, circle_residual, coupler_curve, generate
from linkd.graph import ADJ, TYPE, VALID, from_graph, to_graph
from linkd.mechanism import Mechanism
from linkd.topology import Status
from linkd.validator import validate

SETTINGS = GeneratorSettings()


@pytest.fixture(scope="module")
def samples():
    return generate(96, seed=11)


@pytest.fixture(scope="module")
def checked(samples):
    batch = LinkageBatch.from_graphs(samples.graphs.astype(np.float64))
    return batch, validate(batch, keep_motion=True, backend="numpy")


def test_every_mechanism_is_valid_with_the_margin(checked):
    _, result = checked
    assert (result.status == Status.VALID).all()
    # The generator checks in float32; float64 may differ in the last digits.
    assert result.margin.min() >= SETTINGS.min_margin * (1 - 1e-3)


def test_node_counts_are_balanced_and_as_stored(samples):
    sizes = np.arange(SETTINGS.min_nodes, SETTINGS.max_nodes + 1)
    counts = np.bincount(samples.n_nodes, minlength=sizes[-1] + 1)[sizes]
    assert (counts == len(samples) // len(sizes)).all()
    valid = samples.graphs[:, :, VALID]
    assert (valid.sum(1) == samples.n_nodes).all()
    assert (np.diff(valid, axis=1) <= 0).all()  # valid rows first, then padding


def test_requested_node_count_is_met_exactly():
    for n in (5, 13, 20):
        got = generate(8, seed=n, settings=GeneratorSettings(min_nodes=n, max_nodes=n))
        assert (got.n_nodes == n).all()
        assert (got.graphs[:, :, VALID].sum(1) == n).all()


def test_end_effector_is_last_and_moving_and_every_ground_joint_is_used(samples):
    for graph, n in zip(samples.graphs, samples.n_nodes):
        types = graph[:n, TYPE]
        links = graph[:n, ADJ][:, :n] == 1  # row k: links to earlier joints
        assert types[0] == 1 and types[1] == 0 and types[n - 1] == 0
        for k in np.flatnonzero(types == 1):
            assert links[k + 1 :, k].any(), f"ground joint {k} carries nothing"
        # Moving joints past the crank tip hang on exactly two earlier joints.
        assert (links[2:].sum(1)[types[2:] == 0] == 2).all()


def test_graphs_are_in_canonical_order(samples):
    for graph in samples.graphs[:32]:
        again, _ = to_graph(from_graph(graph.astype(np.float64)), normalise=False)
        np.testing.assert_array_equal(again.astype(np.float32), graph)


def test_stored_curve_is_the_traced_end_effector_path(samples, checked):
    batch, result = checked
    paths = result.end_effector_paths(batch)
    rebuilt = samples.centre[:, None] + samples.scale[:, None, None] * samples.curves
    np.testing.assert_allclose(rebuilt, paths, atol=1e-4)
    centred = paths - paths.mean(1, keepdims=True)
    rms = np.sqrt((centred**2).sum(-1).mean(1))
    np.testing.assert_allclose(samples.curves, centred / rms[:, None, None], atol=1e-4)
    np.testing.assert_allclose(np.sqrt((samples.curves**2).sum(-1).mean(1)), 1, atol=1e-5)


def test_curves_are_genuine_coupler_curves(samples):
    curves = samples.curves.astype(np.float64)
    assert (circle_residual(curves) >= SETTINGS.arc_tolerance).all()
    positions = samples.graphs[:, :, 2:4]
    for curve, pos, n in zip(curves, positions, samples.n_nodes):
        assert coupler_curve(curve[None], pos[None, :n], SETTINGS)[0]


def _paths(mech: Mechanism) -> np.ndarray:
    batch = LinkageBatch.from_mechanisms([mech])
    result = validate(batch, keep_motion=True, backend="numpy")
    assert result.valid[0]
    return result.motion.paths[0]  # (N, T, 2)


def test_arc_detector_flags_rocker_and_crank_joints_but_not_the_coupler_point():
    mech = classic.crank_rocker()  # 3: coupler-rocker joint, 4: coupler point
    # Add joint 5 riding rigidly on the crank (hung on the pivot and the crank tip).
    pos = np.vstack([mech.positions, [[-0.8, 0.6]]])
    on_crank = Mechanism(pos, [*mech.fixed, False], [*mech.links, (0, 5), (1, 5)], (0, 1), 4)
    paths = _paths(on_crank)
    joints = np.repeat(pos[None], 3, 0)
    verdict = coupler_curve(paths[[3, 5, 4]], joints, SETTINGS)
    assert verdict.tolist() == [False, False, True]
    assert circle_residual(paths[[3, 5]]).max() < 1e-9


def test_tiny_and_straight_paths_are_refused():
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    loop = np.stack([np.cos(t), 0.5 * np.sin(2 * t)], -1)
    flat = np.stack([np.cos(t), 0.01 * np.sin(2 * t)], -1)
    joints = np.array([[[-1.0, -1.0], [1.0, 1.0], [1.0, -1.0]]] * 3) * 10
    verdict = coupler_curve(np.stack([loop * 10, loop * 0.1, flat * 10]), joints, SETTINGS)
    assert verdict.tolist() == [True, False, False]


def test_same_seed_same_mechanisms_other_seed_other_ones():
    a, b, c = generate(24, 5), generate(24, 5), generate(24, 6)
    np.testing.assert_array_equal(a.graphs, b.graphs)
    np.testing.assert_array_equal(a.curves, b.curves)
    assert not np.array_equal(a.graphs, c.graphs)


def test_positions_stay_in_the_box_and_joints_apart(samples):
    for graph, n in zip(samples.graphs, samples.n_nodes):
        xy = graph[:n, 2:4]
        assert np.abs(xy).max() <= 1
        gaps = np.linalg.norm(xy[:, None] - xy[None], axis=-1) + np.eye(n) * 9
        assert gaps.min() >= SETTINGS.min_gap * (1 - 1e-6)


def test_settings_refuse_four_joint_mechanisms():
    with pytest.raises(ValueError, match="5"):
        GeneratorSettings(min_nodes=4)
