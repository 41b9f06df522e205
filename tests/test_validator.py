"""Validation verdicts on known mechanisms and on broken graphs, and the per-node check."""

import numpy as np
import pytest
import torch

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.mechanism import Mechanism
from linkd.topology import Status
from linkd.validator import check_new_node, validate, validate_mechanism


@pytest.mark.parametrize(
    "build", [classic.crank_rocker, classic.jansen_leg, classic.watt_six_bar,
              classic.stephenson_six_bar]
)  # fmt: skip
def test_classical_mechanisms_are_valid(build):
    status, margin = validate_mechanism(build())
    assert status == Status.VALID and margin > 0


def test_non_grashof_four_bar_locks():
    status, margin = validate_mechanism(classic.non_grashof_four_bar())
    assert status == Status.LOCKS and margin < 0


def test_overconstrained_graph_is_refused():
    mech = classic.crank_rocker()
    # Coupler point also tied to ground: three links to known joints.
    over = mech.replace(links=[*mech.links, (2, 4)])
    assert validate_mechanism(over)[0] == Status.OVERCONSTRAINED


def test_crank_tip_tied_to_a_second_ground_joint_is_overconstrained():
    mech = classic.crank_rocker()
    assert validate_mechanism(mech.replace(links=[*mech.links, (1, 2)]))[0] == (
        Status.OVERCONSTRAINED
    )


def test_non_dyadic_graph_is_refused():
    mech = classic.crank_rocker()
    # Remove the rocker: the coupler joint hangs on one link only (an extra freedom).
    loose = mech.replace(links=[link for link in mech.links if link != (2, 3)])
    assert validate_mechanism(loose)[0] == Status.NOT_DYADIC


def test_two_free_joints_solvable_together_but_linked_are_overconstrained():
    # Joints 3 and 4 each hang on two ground/crank joints and are also linked to each other.
    pos = [(0, 0), (0, 1), (3, 0), (2, 2), (1, 3)]
    links = [(0, 1), (1, 3), (2, 3), (1, 4), (2, 4), (3, 4)]
    mech = Mechanism(pos, [1, 0, 1, 0, 0], links, (0, 1), 4)
    assert validate_mechanism(mech)[0] == Status.OVERCONSTRAINED


@pytest.mark.parametrize(
    "change, status",
    [
        (lambda m: m.replace(fixed=[0, 0, 1, 0, 0]), Status.BAD_MOTOR),
        (lambda m: m.replace(fixed=[1, 1, 1, 0, 0]), Status.BAD_MOTOR),
        (lambda m: m.replace(links=[link for link in m.links if link != (0, 1)]), Status.BAD_MOTOR),
    ],
)
def test_motor_must_be_a_fixed_pivot_driving_a_free_tip(change, status):
    assert validate_mechanism(change(classic.crank_rocker()))[0] == status


def test_coincident_joints_and_zero_length_links_are_refused():
    mech = classic.crank_rocker()
    pos = mech.positions.copy()
    pos[4] = pos[3]
    assert validate_mechanism(mech.replace(positions=pos))[0] == Status.ZERO_LENGTH_LINK
    pos = mech.positions.copy()
    pos[4] = pos[2]  # coupler point on the rocker pivot, not linked to it
    assert validate_mechanism(mech.replace(positions=pos))[0] == Status.COINCIDENT_JOINTS


def test_margin_shrinks_towards_a_toggle():
    base = classic.crank_rocker()
    margins = []
    for crank in (0.5, 1.0, 1.4):
        pos = base.positions.copy()
        pos[1] = [0, crank]
        margins.append(validate_mechanism(base.replace(positions=pos))[1])
    assert margins[0] > margins[1] > margins[2] > 0


def test_batch_verdicts_match_single_verdicts():
    mechs = [classic.jansen_leg(), classic.non_grashof_four_bar(), classic.watt_six_bar()]
    result = validate(LinkageBatch.from_mechanisms(mechs))
    assert [Status(s) for s in result.status] == [validate_mechanism(m)[0] for m in mechs]


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_node_by_node_check_agrees_with_full_validation(backend):
    """Grow each classic mechanism node by node in graph order; every prefix check passes,
    and a broken proposal for the last node fails."""
    from linkd.graph import to_graph
    from linkd.kinematics import trace
    from linkd.topology import assembly_plan

    for mech in [classic.jansen_leg(), classic.stephenson_six_bar()]:
        graph, _ = to_graph(mech)
        batch = LinkageBatch.from_graphs(graph[None])
        plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
        paths = trace(batch.positions, plan, 200).paths  # (1, N, T, 2)
        n = int(batch.valid.sum())
        wrap = (lambda a: torch.tensor(a)) if backend == "torch" else np.asarray
        for t in range(n):
            ok, path, _ = check_new_node(
                wrap(paths[:, :t]), wrap(batch.fixed[:, :t]), wrap(batch.fixed[:, t]),
                wrap(batch.positions[:, t]), wrap(batch.adjacency[:, t, :t]),
            )  # fmt: skip
            assert bool(ok[0]), t
            np.testing.assert_allclose(np.asarray(path[0]), paths[0, t], atol=1e-9)
        # A third link on the last joint over-constrains it.
        links = batch.adjacency[:, n - 1, : n - 1].copy()
        links[0, np.flatnonzero(~links[0])[0]] = True
        ok, _, _ = check_new_node(
            wrap(paths[:, : n - 1]), wrap(batch.fixed[:, : n - 1]), wrap(batch.fixed[:, n - 1]),
            wrap(batch.positions[:, n - 1]), wrap(links),
        )  # fmt: skip
        assert not bool(ok[0])


def test_node_check_refuses_a_dyad_that_cannot_close():
    mech = classic.non_grashof_four_bar()
    batch = LinkageBatch.from_mechanisms([mech])
    from linkd.kinematics import crank_path, ops_for

    angles = np.arange(200) * 2 * np.pi / 200
    ops = ops_for(batch.positions)
    tip = np.stack(crank_path(batch.positions[:, 0], batch.positions[:, 1], angles, ops), -1)
    prefix = np.stack([np.repeat(batch.positions[:, 0, None], 200, 1), tip,
                       np.repeat(batch.positions[:, 2, None], 200, 1)], 1)  # fmt: skip
    ok, _, margin = check_new_node(
        prefix, batch.fixed[:, :3], batch.fixed[:, 3], batch.positions[:, 3],
        batch.adjacency[:, 3, :3],
    )  # fmt: skip
    assert not ok[0] and margin[0] < 0
