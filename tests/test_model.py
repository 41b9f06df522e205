"""LinkD model: causality, incremental decoding, the diffused node form, checkpoints, learning."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from linkd import classic
from linkd.graph import ADJ, MAX_NODES, TYPE, VALID, to_graph
from linkd.model import LinkD, LinkDConfig, load_checkpoint, save_checkpoint
from linkd.model.linkd import link_mask, to_rows, to_target

pytestmark = pytest.mark.usefixtures("one_thread")

TINY = LinkDConfig(dim=32, layers=2, heads=2, encoder_layers=1, head_widths=(32, 16), head_cond=16)


def graphs_of(*mechanisms) -> torch.Tensor:
    return torch.tensor(np.stack([to_graph(m)[0] for m in mechanisms]), dtype=torch.float32)


def randomised(model: LinkD) -> LinkD:
    """Non-zero weights everywhere (adaLN starts at zero, which would hide the attention)."""
    torch.manual_seed(1)
    with torch.no_grad():
        for p in model.parameters():
            p.add_(0.1 * torch.randn_like(p))
    return model.eval()


def test_loss_is_finite_and_reaches_every_parameter():
    torch.manual_seed(0)
    model = LinkD(TINY)
    graphs = graphs_of(classic.jansen_leg(), classic.crank_rocker())
    loss, parts = model(graphs, torch.randn(2, 200, 2))
    loss.backward()
    assert torch.isfinite(loss) and set(parts) == {"validity", "type", "position", "links"}
    assert all(p.grad is not None for p in model.parameters())


def test_dropped_curves_train_the_null_curve_and_ignore_the_curve():
    model = LinkD(replace(TINY, curve_dropout=1.0)).train()
    graphs = graphs_of(classic.jansen_leg(), classic.crank_rocker())
    losses = []
    for curves in (torch.randn(2, 200, 2), torch.randn(2, 200, 2)):
        model.zero_grad()
        torch.manual_seed(0)
        loss = model(graphs, curves)[0]
        loss.backward()
        losses.append(loss.item())
    assert model.null_curve.grad.abs().sum() > 0
    assert losses[0] == pytest.approx(losses[1], abs=1e-6)  # every curve was dropped


CROSS = replace(TINY, cross_attention=True)


@pytest.mark.parametrize("config", [TINY, CROSS])
def test_context_of_node_t_sees_only_earlier_nodes(config):
    model = randomised(LinkD(config))
    graphs = graphs_of(classic.jansen_leg())
    cond = torch.randn(1, 4, config.dim)
    changed = graphs.clone()
    changed[0, 4, 2:4] += 0.3  # move joint 4
    with torch.no_grad():
        h, h2 = model.backbone(graphs[:, :-1], cond), model.backbone(changed[:, :-1], cond)
    same = (h - h2).abs().amax(-1)[0]
    assert torch.all(same[:5] == 0)  # h_0..h_4 precede joint 4
    assert torch.all(same[5:] > 1e-6)


@pytest.mark.parametrize("config", [TINY, CROSS])
def test_cached_decoding_matches_the_full_pass(config):
    model = randomised(LinkD(config))
    graphs = graphs_of(classic.jansen_leg(), classic.watt_six_bar())
    cond = torch.randn(2, 4, config.dim)
    with torch.no_grad():
        full = model.backbone(graphs[:, :-1], cond)
        cache = model.new_cache()
        steps = [model.backbone(graphs[:, :0], cond, cache)[:, -1]]
        for t in range(MAX_NODES - 1):
            steps.append(model.backbone(graphs[:, t : t + 1], cond, cache)[:, -1])
    torch.testing.assert_close(torch.stack(steps, 1), full, atol=1e-5, rtol=1e-5)


def test_diffused_form_decodes_back_to_the_graph():
    graphs = graphs_of(classic.jansen_leg(), classic.stephenson_six_bar())
    for graph in graphs:
        index = torch.arange(MAX_NODES)
        for dyadic in (False, True):
            rows = to_rows(to_target(graph), index, dyadic)
            np.testing.assert_array_equal(rows.numpy(), graph.numpy())
    target = to_target(graphs)
    assert set(target[..., VALID].unique().tolist()) == {-1.0, 1.0}
    assert set(target[..., ADJ].unique().tolist()) == {-1.0, 1.0}


def test_dyadic_decoding_gives_each_joint_the_links_of_a_dyad():
    """A moving joint keeps its two likeliest links to earlier joints, the crank tip its one,
    a ground joint none; each link on its own would keep every positive estimate."""
    x0 = torch.full((4, 24), -1.0)
    x0[:, VALID] = 1.0
    x0[:, TYPE] = torch.tensor([1.0, -1.0, -1.0, 1.0])  # pivot, crank tip, joint, ground
    x0[:, ADJ] = torch.linspace(-0.9, 0.9, 20)  # the later an earlier joint, the likelier
    x0[1, ADJ.start] = -0.5  # the crank tip's only link is unlikely, yet the one it must have
    index = torch.tensor([0, 1, 5, 6])
    rows = to_rows(x0, index, dyadic=True)
    links = (rows[:, ADJ] == 1).int()
    assert links.sum(1).tolist() == [0, 1, 2, 0]
    assert links[1, 0] == 1 and links[2, 3:5].tolist() == [1, 1]  # the likeliest two
    assert (rows[:, ADJ][~link_mask(index)] == -1).all()  # no links to later joints
    plain = (to_rows(x0, index)[:, ADJ] == 1).sum(1).tolist()
    assert plain == [0, 0, 0, 0]  # only positive estimates: the first joints' are negative


def test_checkpoint_round_trip(tmp_path):
    model = randomised(LinkD(TINY))
    save_checkpoint(tmp_path / "m.pt", model, meta={"note": "test"})
    loaded, state = load_checkpoint(tmp_path / "m.pt")
    assert loaded.config == TINY and state["meta"] == {"note": "test"}
    curves = torch.randn(3, 200, 2)
    with torch.no_grad():
        torch.testing.assert_close(loaded.encode(curves), model.encode(curves))


@pytest.mark.parametrize(
    ("mechanism", "config"), [(classic.jansen_leg, TINY), (classic.watt_six_bar, CROSS)]
)
def test_learns_to_reproduce_one_mechanism(mechanism, config):
    """Teacher forcing on one graph and curve: sampling then rebuilds that graph."""
    torch.manual_seed(0)
    model = LinkD(replace(config, sample_coins=False))  # the likelier side, every time
    graphs = graphs_of(mechanism()).expand(16, -1, -1)
    curves = torch.randn(1, 200, 2).expand(16, -1, -1)
    opt = torch.optim.AdamW(model.parameters(), 3e-3)
    for _ in range(200):
        loss, _ = model(graphs, curves)
        opt.zero_grad()
        loss.backward()
        opt.step()
    from linkd.sample import grow

    model.eval()
    with torch.no_grad():
        out = grow(model, model.encode(curves[:8]), torch.Generator().manual_seed(0), steps=20)
    truth = graphs[:8]
    discrete = torch.ones(out.shape[-1], dtype=torch.bool)
    discrete[2:4] = False
    assert torch.equal(out[..., discrete], truth[..., discrete])
    assert (out[..., 2:4] - truth[..., 2:4]).abs().max() < 0.1


@pytest.mark.parametrize("logit", [0.0, 2.0])
def test_validity_and_type_are_drawn_with_the_predicted_odds(logit):
    """A head that predicts validity and ground with odds e^logit: coins follow those odds,
    deterministic DDIM always takes the likelier side."""
    model = LinkD(TINY).eval()
    with torch.no_grad():
        last = model.head.out[1]
        last.weight.zero_()
        last.bias.zero_()
        last.bias[VALID] = logit
        last.bias[1] = logit
    context = torch.randn(4000, TINY.dim)
    index = torch.full((4000,), 5)
    rows = model.denoise(context, index, generator=torch.Generator().manual_seed(0))
    p = 1 / (1 + np.exp(-logit))
    assert abs(float((rows[:, VALID] > 0.5).float().mean()) - p) < 0.03
    valid = rows[:, VALID] > 0.5
    assert abs(float((rows[valid, 1] > 0.5).float().mean()) - p) < 0.03
    model.config = replace(TINY, sample_coins=False)
    rows = model.denoise(context, index, generator=torch.Generator().manual_seed(0))
    assert bool((rows[:, VALID] > 0.5).all()) == (logit > 0)
