"""Sampling: the API the design pipeline uses, determinism, and what each strategy guarantees."""

import numpy as np
import pytest
import torch

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.errors import InputError
from linkd.graph import from_graph, to_graph
from linkd.model import LinkD, LinkDConfig
from linkd.sample import Samples, check_graphs, load_model, sample
from linkd.topology import Status
from linkd.validator import validate_mechanism

TINY = LinkDConfig(dim=32, layers=2, heads=2, encoder_layers=1, head_widths=(32, 16), head_cond=16)


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def model_and_curves():
    """A small model taught two mechanisms, each for its own curve: it samples them with
    some noise, so some designs are valid and some are not. (One thread: the same model on
    every machine.)"""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    mechanisms = [classic.jansen_leg(), classic.watt_six_bar()]
    graphs = torch.tensor(np.stack([to_graph(m)[0] for m in mechanisms]), dtype=torch.float32)
    curves = torch.randn(2, 200, 2)
    model = LinkD(TINY)
    opt = torch.optim.AdamW(model.parameters(), 3e-3)
    for _ in range(120):
        loss, _ = model(graphs.repeat(8, 1, 1), curves.repeat(8, 1, 1))
        opt.zero_grad()
        loss.backward()
        opt.step()
    torch.set_num_threads(threads)
    return model.eval(), curves.numpy()


def test_samples_have_the_documented_form(model_and_curves):
    model, curves = model_and_curves
    out = sample(model, curves, 5, "oneshot", seed=0)
    assert isinstance(out, Samples)
    assert out.graphs.shape == (10, 20, 24) and out.graphs.dtype == np.float32
    np.testing.assert_array_equal(out.curve_index, np.repeat([0, 1], 5))
    assert out.valid.dtype == bool and out.valid.shape == (10,)
    discrete = np.delete(out.graphs, [2, 3], axis=2)
    assert set(np.unique(discrete)) <= {-1.0, 0.0, 1.0}


@pytest.mark.parametrize("strategy", ["oneshot", "graph", "node"])
def test_sampling_is_deterministic_for_a_seed(model_and_curves, strategy):
    model, curves = model_and_curves
    a = sample(model, curves, 4, strategy, seed=3, retries=3)
    b = sample(model, curves, 4, strategy, seed=3, retries=3)
    c = sample(model, curves, 4, strategy, seed=4, retries=3)
    np.testing.assert_array_equal(a.graphs, b.graphs)
    assert not np.array_equal(a.graphs, c.graphs)


def test_valid_flag_is_the_full_validation(model_and_curves):
    """Valid: a working linkage whose end effector moves (a design that traces no path is no
    design)."""
    from linkd.design.select import end_effector_path
    from linkd.sample import MOVES, spread

    model, curves = model_and_curves
    out = sample(model, curves, 12, "oneshot", seed=1)
    for graph, ok in zip(out.graphs, out.valid):
        try:
            mech = from_graph(graph)
            status = validate_mechanism(mech)[0]
        except ValueError:  # fewer than two joints
            status = Status.BAD_MOTOR
        moves = status == Status.VALID and spread(end_effector_path(mech, 200)[0]) > MOVES
        assert ok == moves


def test_graph_retry_regrows_only_invalid_graphs(model_and_curves):
    model, curves = model_and_curves
    once = sample(model, curves, 16, "oneshot", seed=2)
    retried = sample(model, curves, 16, "graph", seed=2)
    np.testing.assert_array_equal(retried.graphs[once.valid], once.graphs[once.valid])
    assert retried.valid.sum() >= once.valid.sum()
    np.testing.assert_array_equal(check_graphs(retried.graphs)[0], retried.valid)


def test_node_retry_is_at_least_as_valid_as_one_shot(model_and_curves):
    model, curves = model_and_curves
    once = sample(model, curves, 16, "oneshot", seed=5)
    node = sample(model, curves, 16, "node", seed=5)
    assert node.valid.mean() >= once.valid.mean()
    assert node.valid.any()


def jansen_joints() -> tuple[torch.Tensor, torch.Tensor]:
    """The Jansen leg's graph matrix (20, 24) and its joints' paths (1, 20, T, 2)."""
    from linkd.validator import validate

    graph = torch.tensor(to_graph(classic.jansen_leg())[0], dtype=torch.float32)
    batch = LinkageBatch.from_graphs(graph[None].numpy())
    motion = validate(batch, keep_motion=True, backend="numpy").motion
    return graph, torch.as_tensor(np.stack([motion.x, motion.y], -1), dtype=torch.float32)


def unclosable(graph: torch.Tensor, t: int) -> torch.Tensor:
    """Joint t of `graph` (1, 24), moved too far from its parents for the dyad to close."""
    row = graph[t][None].clone()
    row[0, 2:4] += 5.0
    return row


def test_node_check_accepts_true_joints_and_rejects_broken_ones():
    """The per-node check used by node-level retry, on the Jansen leg's own joints."""
    from linkd.sample import _check_node
    from linkd.validator import N_ANGLES

    graph, paths = jansen_joints()
    assert paths.shape[2] == N_ANGLES
    t = 6
    prefix, fixed = paths[:, :t], graph[None, :t, 1] > 0.5
    true = graph[t][None]
    too_many = true.clone()
    too_many[0, 4 : 4 + t] = torch.where(torch.arange(t) < 3, 1.0, too_many[0, 4 : 4 + t])
    too_far = unclosable(graph, t)
    stop = torch.tensor(to_graph(classic.crank_rocker())[0][19], dtype=torch.float32)[None]
    ok = [_check_node(row, t, prefix, fixed)[0].item() for row in (true, too_many, too_far, stop)]
    assert ok == [True, False, False, True]
    assert not _check_node(stop, 2, paths[:, :2], fixed[:, :2])[0].item()  # too early to stop
    # the path the check computes for the new joint is the joint's true path
    torch.testing.assert_close(_check_node(true, t, prefix, fixed)[1][0], paths[0, t])


def test_a_joint_that_fails_every_proposal_ends_its_graph_after_the_last_moving_joint():
    """Node-level retry: when every proposal for joint t fails, the graph ends after the last
    joint before it that moves (from the third on), any ground joints after that dropped too:
    a valid, shorter design. Where no such joint exists yet, the failing proposal stays."""
    from linkd.sample import _end_failed

    graph, paths = jansen_joints()
    failed = unclosable(graph, 6)
    grounded = graph.clone()  # joint 5 made a ground joint after the first five
    grounded[5, 1], grounded[5, 4:] = 1.0, torch.where(grounded[5, 4:] == 1, 0.0, grounded[5, 4:])
    still = paths.clone()
    still[:, 5] = still[:, 5, :1]
    for start, prefix, joints in ((graph, paths, 6), (grounded, still, 5)):
        graphs = start[None].clone()
        rows = _end_failed(graphs, torch.tensor([0]), 6, failed, torch.tensor([False]),
                           prefix[:, :6])  # fmt: skip
        assert rows[0, 0] == 0 and (rows[0, 4:] == -1).all()  # a stop row instead of joint 6
        graphs[0, 6] = rows[0]
        design = from_graph(graphs[0].numpy())
        assert design.n_nodes == joints and validate_mechanism(design)[0] == Status.VALID
    kept = _end_failed(graph[None].clone(), torch.tensor([0]), 2, failed, torch.tensor([False]),
                       paths[:, :2])  # fmt: skip
    assert kept[0, 0] == 1  # two joints are no mechanism yet: the failing joint stays
    accepted = _end_failed(graph[None].clone(), torch.tensor([0]), 6, graph[6][None],
                           torch.tensor([True]), paths[:, :6])  # fmt: skip
    torch.testing.assert_close(accepted, graph[6][None])


def test_bad_arguments_are_input_errors(model_and_curves, tmp_path):
    model, curves = model_and_curves
    with pytest.raises(InputError, match="strategy"):
        sample(model, curves, 1, "beam")
    with pytest.raises(InputError, match="curves"):
        sample(model, curves[0], 1)
    with pytest.raises(InputError, match="no such checkpoint"):
        load_model(tmp_path / "missing.pt")


def test_shipped_model_designs_valid_linkages_for_generated_curves():
    from linkd.generator import generate
    from linkd.training_data import conditioning

    model = load_model()
    curves = conditioning(torch.as_tensor(generate(8, 11).curves)).numpy()
    out = sample(model, curves, 8, "node", seed=0)
    assert out.valid.mean() >= 0.9  # 98.8% on 300 test curves (model card)
