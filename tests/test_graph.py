"""The N x 24 graph matrix: canonical order, lossless round trips, decoding."""

import numpy as np
import pytest

from linkd import classic
from linkd.graph import ADJ, FEATURES, MAX_NODES, TYPE, VALID, canonical_order, from_graph, to_graph
from linkd.mechanism import Mechanism
from linkd.validator import validate_mechanism


def _same_mechanism(a: Mechanism, b: Mechanism) -> bool:
    """Equal up to relabelling: compare through the canonical order."""
    ca, cb = a.relabelled(canonical_order(a)), b.relabelled(canonical_order(b))
    return (
        np.allclose(ca.positions, cb.positions)
        and (ca.fixed == cb.fixed).all()
        and ca.links == cb.links
        and ca.end_effector == cb.end_effector
    )


@pytest.mark.parametrize(
    "build", [classic.crank_rocker, classic.jansen_leg, classic.watt_six_bar,
              classic.stephenson_six_bar]
)  # fmt: skip
def test_round_trip_is_lossless(build):
    mech = build()
    graph, frame = to_graph(mech)
    assert graph.shape == (MAX_NODES, FEATURES)
    assert np.abs(graph[:, 2:4]).max() <= 1 + 1e-12
    assert _same_mechanism(from_graph(graph, frame), mech)


def test_layout_follows_the_paper():
    mech = classic.jansen_leg()
    graph, _ = to_graph(mech)
    n = mech.n_nodes
    assert (graph[:n, VALID] == 1).all() and (graph[n:, VALID] == 0).all()
    assert graph[0, TYPE] == 1 and graph[1, TYPE] == 0 and (graph[n:, TYPE] == -1).all()
    adj = graph[:, ADJ]
    for k in range(MAX_NODES):
        assert (adj[k, k:] == -1).all()
        if k < n:
            assert set(adj[k, :k]) <= {0.0, 1.0}
    assert adj[1, 0] == 1  # the crank
    moving = [k for k in range(2, n) if graph[k, TYPE] == 0]
    assert all(adj[k, :k].sum() == 2 for k in moving)


def test_canonical_order_puts_motor_first_and_end_effector_last():
    mech = classic.stephenson_six_bar()
    shuffled = mech.relabelled([7, 3, 5, 0, 2, 6, 1, 4])
    order = canonical_order(shuffled)
    assert order[:2] == list(shuffled.motor) and order[-1] == shuffled.end_effector
    assert _same_mechanism(from_graph(*to_graph(shuffled)), mech)


def test_every_prefix_of_a_graph_is_a_valid_mechanism():
    graph, _ = to_graph(classic.jansen_leg())
    for n in range(2, 9):
        prefix = graph.copy()
        prefix[n:, VALID] = 0
        status, _ = validate_mechanism(from_graph(prefix))
        assert status == 0, n


def test_end_effector_that_drives_other_joints_cannot_be_last():
    mech = classic.jansen_leg().replace(end_effector=5)  # the hip drives the shin
    with pytest.raises(ValueError, match="end effector"):
        to_graph(mech)


def test_non_dyadic_mechanism_has_no_graph():
    mech = classic.crank_rocker()
    with pytest.raises(ValueError, match="not dyadic"):
        to_graph(mech.replace(links=[link for link in mech.links if link != (2, 3)]))


def test_batch_graph_matrices_round_trip():
    from linkd.batch import LinkageBatch
    from linkd.generator import generate

    graphs = generate(16, 4).graphs
    np.testing.assert_array_equal(LinkageBatch.from_graphs(graphs).to_graphs(), graphs)
