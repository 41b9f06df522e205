"""Joints that add nothing to the end effector's motion are dropped (linkd.design.prune)."""

import numpy as np

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.design.prune import pruned
from linkd.design.rounds import with_coupler_point
from linkd.design.select import topology_key
from linkd.generator import generate
from linkd.validator import validate


def _paths(batch: LinkageBatch) -> np.ndarray:
    motion = validate(batch, keep_motion=True, backend="numpy")  # float64
    assert motion.valid.all()
    return motion.end_effector_paths(batch)


def test_pruning_keeps_the_path_and_drops_what_growth_left_behind():
    batch = LinkageBatch.from_graphs(generate(120, seed=3).graphs)
    batch = batch.subset(np.flatnonzero(batch.valid.sum(1) <= 16))
    batch = batch.subset(np.flatnonzero(validate(batch).valid))
    grown, rng = batch, np.random.default_rng(0)
    for _ in range(3):  # three rounds' growth: chains of coupler points
        grown = with_coupler_point(grown.subset(np.arange(len(grown))), rng)
    small = pruned(grown)
    np.testing.assert_allclose(_paths(small), _paths(grown), atol=1e-9)
    joints = small.valid.sum(1)
    assert (joints <= grown.valid.sum(1)).all()
    # The chains collapse: about as many joints as the designs had before growing, pruned too.
    assert joints.mean() <= pruned(batch).valid.sum(1).mean() + 1 < grown.valid.sum(1).mean() - 2
    assert (small.end_effector == small.valid.sum(1) - 1).all()
    assert (small.fixed[:, 0] & ~small.fixed[:, 1]).all()  # motor pivot and crank tip stay
    for row in range(len(small)):  # every moving joint still hangs on two joints before it
        n = int(small.valid[row].sum())
        parents = np.tril(small.adjacency[row, :n, :n], -1).sum(1)
        assert (parents[2:][~small.fixed[row, 2:n]] == 2).all()


def test_a_chain_of_coupler_points_hangs_on_its_body():
    four_bar = LinkageBatch.from_mechanisms([classic.crank_rocker()])
    graphs = np.full((1, 8, 24), -1.0, np.float32)
    graphs[:, :5] = four_bar.to_graphs()[0]
    batch = LinkageBatch.from_graphs(graphs)
    rng = np.random.default_rng(1)
    for _ in range(3):  # each new end effector on a link at the old one: all on one body
        batch.end_effector[:] = batch.valid.sum(1) - 1
        ee = int(batch.end_effector[0])
        partner = int(np.flatnonzero(batch.adjacency[0, ee, :ee])[0])
        new = ee + 1
        batch.positions[0, new] = batch.positions[0, ee] + rng.normal(0, 0.5, 2)
        batch.valid[0, new] = True
        batch.adjacency[0, new, [ee, partner]] = batch.adjacency[0, [ee, partner], new] = True
        batch.end_effector[:] = new
    small = pruned(batch)
    assert small.valid.sum() == 5  # the four-bar and one coupler point
    np.testing.assert_allclose(_paths(small), _paths(batch), atol=1e-9)
    # A mechanism with nothing to drop is left as it is.
    same = pruned(four_bar)
    assert topology_key(same, 0) == topology_key(four_bar, 0)
    np.testing.assert_array_equal(same.positions, four_bar.positions)
