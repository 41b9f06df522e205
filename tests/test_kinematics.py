"""Forward kinematics: classical mechanisms, torch/numpy agreement, gradients, padding."""

import numpy as np
import pytest
import torch

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.kinematics import trace
from linkd.topology import assembly_plan
from linkd.validator import validate


def _motion(mechs, backend="numpy", n_angles=200):
    batch = LinkageBatch.from_mechanisms(mechs)
    result = validate(batch, n_angles, keep_motion=True, backend=backend)
    return batch, result


def test_jansen_foot_path_has_the_known_extent():
    batch, result = _motion([classic.jansen_leg()], n_angles=2000)
    assert result.valid.all()
    extent = np.ptp(result.end_effector_paths(batch)[0], axis=0)
    np.testing.assert_allclose(extent, [67.9, 22.5], atol=0.1)


def test_link_lengths_stay_constant_over_the_cycle():
    for mech in [classic.jansen_leg(), classic.watt_six_bar(), classic.stephenson_six_bar()]:
        batch, result = _motion([mech])
        paths = result.motion.paths[0]  # (N, T, 2)
        lengths = np.linalg.norm(paths[:, None] - paths[None, :], axis=-1)  # (N, N, T)
        adj = batch.adjacency[0]
        spread = np.ptp(lengths[adj], axis=-1)
        assert spread.max() < 1e-9 * max(1.0, mech.scale)


def test_crank_turns_counter_clockwise_once_from_the_assembly_pose():
    mech = classic.crank_rocker()
    _, result = _motion([mech], n_angles=8)
    tip = result.motion.paths[0, 1]
    np.testing.assert_allclose(tip[0], mech.positions[1])
    rel = tip - mech.positions[0]
    angles = np.unwrap(np.arctan2(rel[:, 1], rel[:, 0]))
    np.testing.assert_allclose(np.diff(angles), 2 * np.pi / 8)


def test_torch_and_numpy_agree_in_float64():
    mechs = [classic.jansen_leg(), classic.crank_rocker(), classic.watt_six_bar()]
    batch = LinkageBatch.from_mechanisms(mechs)
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    ref = trace(batch.positions, plan, 64)
    got = trace(torch.tensor(batch.positions), plan, 64)
    np.testing.assert_allclose(got.paths.numpy(), ref.paths, atol=1e-10)
    np.testing.assert_allclose(got.step_margin.numpy(), ref.step_margin, atol=1e-10)


def test_padded_batch_matches_one_at_a_time():
    mechs = [classic.crank_rocker(), classic.jansen_leg(), classic.stephenson_six_bar()]
    batch, result = _motion(mechs)
    for k, mech in enumerate(mechs):
        single_batch, single = _motion([mech])
        np.testing.assert_allclose(
            result.end_effector_paths(batch)[k], single.end_effector_paths(single_batch)[0]
        )
        assert result.margin[k] == pytest.approx(single.margin[0])


def test_gradients_flow_to_every_joint_position():
    batch = LinkageBatch.from_mechanisms([classic.jansen_leg()])
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    pos = torch.tensor(batch.positions, requires_grad=True)
    motion = trace(pos, plan, 50, full=True)
    foot = motion.paths[0, batch.end_effector[0]]
    (foot.pow(2).sum() + motion.sin2.sum()).backward()
    assert torch.isfinite(pos.grad).all()
    assert (pos.grad.abs().sum(-1) > 0).all()


def test_gradient_matches_finite_differences():
    batch = LinkageBatch.from_mechanisms([classic.crank_rocker()])
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)

    def loss(p):
        return trace(p, plan, 16).paths[0, 4].sum()

    pos = torch.tensor(batch.positions, requires_grad=True)
    assert torch.autograd.gradcheck(loss, (pos,), eps=1e-6, atol=1e-5)


def test_gradient_of_a_padded_batch_matches_finite_differences():
    # Several dyads deep, padded plans (unused steps), paths, transmissions and margins at once:
    # the reverse walk through the steps (`linkd.dyad_chain`) against finite differences.
    mechs = [classic.jansen_leg(), classic.crank_rocker(), classic.stephenson_six_bar()]
    batch = LinkageBatch.from_mechanisms(mechs)
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    weights = torch.linspace(-1, 1, batch.positions.size).reshape(batch.positions.shape)

    def loss(p):
        motion = trace(p, plan, 12, full=True)
        return (motion.paths.sum(2) * weights).sum() + motion.sin2.sum() + motion.margin.sum()

    pos = torch.tensor(batch.positions, requires_grad=True)
    assert torch.autograd.gradcheck(loss, (pos,), eps=1e-6, atol=1e-5)


def test_float32_and_cuda_free_path_runs():
    batch = LinkageBatch.from_mechanisms([classic.jansen_leg()])
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    motion = trace(torch.tensor(batch.positions, dtype=torch.float32), plan, 32)
    assert motion.paths.dtype == torch.float32
    assert torch.isfinite(motion.paths).all()
