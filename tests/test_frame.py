"""The principal frame of a canonical model: the same shape in any orientation reads the same,
and what the model makes of it turns with the curve."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from linkd import classic
from linkd.design.select import end_effector_path
from linkd.geometry import rotation
from linkd.graph import VALID, XY, to_graph
from linkd.model import LinkD, LinkDConfig
from linkd.model.frame import principal_turn, turned
from linkd.sample import sample
from linkd.training_data import conditioning

pytestmark = pytest.mark.usefixtures("one_thread")

CANONICAL = LinkDConfig(dim=32, layers=2, heads=2, encoder_layers=1, head_widths=(32, 16),
                        head_cond=16, cross_attention=True, canonical=True)  # fmt: skip


def coupler_curve() -> torch.Tensor:
    """(1, 200, 2) the crank-rocker's normalised coupler curve (no symmetry to confuse a frame)."""
    path = end_effector_path(classic.crank_rocker(), 400)[0]
    return conditioning(torch.as_tensor(path[None], dtype=torch.float32))


def turned_by(points: torch.Tensor, angle: float, reflect: bool = False) -> torch.Tensor:
    return points @ torch.as_tensor(rotation(angle, reflect=reflect).T, dtype=points.dtype)


@pytest.mark.parametrize("angle", [0.3, 2.0, -2.8])
def test_a_turned_curve_has_the_same_principal_form(angle):
    curve = coupler_curve()
    other = turned_by(curve, angle)
    form = curve @ principal_turn(curve).transpose(1, 2)
    assert torch.allclose(other @ principal_turn(other).transpose(1, 2), form, atol=1e-5)
    turn = principal_turn(other)[0]
    assert torch.allclose(turn @ turn.T, torch.eye(2), atol=1e-6) and torch.det(turn) > 0


def test_the_principal_axis_is_the_long_one_and_the_curve_leans_its_way():
    stretched = coupler_curve() * torch.tensor([0.2, 3.0])  # longest along y
    form = stretched @ principal_turn(stretched).transpose(1, 2)
    spread = form[0].var(0)
    assert spread[0] > spread[1]
    assert (form[0, :, 0] ** 3).mean() >= 0


def test_turned_moves_only_valid_joints():
    graphs = torch.as_tensor(to_graph(classic.jansen_leg())[0][None], dtype=torch.float32)
    turn = torch.as_tensor(rotation(0.7)[None], dtype=torch.float32)
    out = turned(graphs, turn)
    valid = graphs[0, :, VALID] > 0.5
    assert torch.allclose(out[0, valid][:, XY], graphs[0, valid][:, XY] @ turn[0].T)
    assert torch.equal(out[0, ~valid], graphs[0, ~valid])
    assert torch.equal(out[..., 4:], graphs[..., 4:])


def test_a_canonical_model_is_blind_to_the_orientation_of_the_pair():
    torch.manual_seed(0)
    model = LinkD(CANONICAL).eval()
    graphs = torch.as_tensor(to_graph(classic.crank_rocker())[0][None], dtype=torch.float32)
    curve = coupler_curve()
    turn = torch.as_tensor(rotation(1.1)[None], dtype=torch.float32)
    losses = []
    for g, c in ((graphs, curve), (turned(graphs, turn), curve @ turn.transpose(1, 2))):
        torch.manual_seed(3)
        losses.append(model(g, c)[0].item())
    assert losses[0] == pytest.approx(losses[1], rel=1e-4)
    plain = LinkD(replace(CANONICAL, canonical=False)).eval()
    plain.load_state_dict(model.state_dict())
    torch.manual_seed(3)
    assert plain(turned(graphs, turn), curve @ turn.transpose(1, 2))[0].item() != pytest.approx(
        losses[0], rel=1e-4
    )


def test_a_canonical_model_samples_turn_with_the_curve():
    torch.manual_seed(0)
    model = LinkD(CANONICAL).eval()
    curve = coupler_curve().numpy()
    turn = rotation(2.4).astype(np.float32)
    first = sample(model, curve, 4, "oneshot", seed=5).graphs
    second = sample(model, curve @ turn.T, 4, "oneshot", seed=5).graphs
    assert np.array_equal(first[..., 4:], second[..., 4:])  # the same joints and links
    assert np.allclose(first[..., XY] @ turn.T, second[..., XY], atol=1e-4)
