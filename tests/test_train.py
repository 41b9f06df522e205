"""Training: conditioning curves, joint augmentation, batches, schedule, determinism, DDP."""

import itertools
import socket
from dataclasses import replace

import numpy as np
import pytest
import torch
import torch.multiprocessing as mp

from linkd.batch import LinkageBatch
from linkd.curves import chamfer_batch, curve_moments
from linkd.generator import generate
from linkd.graph import VALID
from linkd.model import LinkD, load_checkpoint
from linkd.train import PRESETS, epoch_batches, lr_at, train
from linkd.training_data import (
    FILL,
    PATH_RADIUS,
    TrainData,
    augment,
    conditioning,
    curve_frame,
    resample_closed,
)
from linkd.validator import validate


@pytest.fixture(scope="module")
def data() -> TrainData:
    s = generate(96, 3)
    return TrainData(
        torch.as_tensor(s.graphs), torch.as_tensor(s.curves), torch.as_tensor(s.n_nodes).long()
    )


def tiny(tmp_path, **changes):
    return replace(PRESETS["tiny"], out=str(tmp_path), threads=1, **changes)


def test_arc_length_resampling_spaces_points_evenly_from_any_start():
    t = torch.linspace(0, 1, 400)[:-1] ** 1.5 * 2 * np.pi  # points bunched near the start
    curves = torch.stack([t.cos(), 2 * t.sin()], -1)[None].expand(2, -1, -1)
    out = resample_closed(curves, 200, torch.tensor([0.0, 0.25]))
    step = (out.roll(-1, 1) - out).norm(dim=-1)
    assert step.std(1).max() / step.mean() < 0.02
    # the second copy starts a quarter of the length later: the same points, shifted by 50
    torch.testing.assert_close(out[1], out[0].roll(-50, 0), atol=2e-3, rtol=0)


def test_conditioning_is_normalised_and_random_only_with_a_generator(data):
    fixed = conditioning(data.curves[:8])
    centroid, radius = curve_moments(fixed)
    torch.testing.assert_close(centroid, torch.zeros(8, 2), atol=1e-5, rtol=0)
    torch.testing.assert_close(radius, torch.ones(8), atol=1e-5, rtol=0)
    torch.testing.assert_close(conditioning(data.curves[:8]), fixed)
    shuffled = conditioning(data.curves[:8], torch.Generator().manual_seed(0))
    assert not torch.allclose(shuffled, fixed)
    # same point set, just another start and direction
    assert chamfer_batch(shuffled.double(), fixed.double()).max() < 0.05


def test_augmented_mechanisms_trace_the_augmented_curves(data):
    gen = torch.Generator().manual_seed(0)
    graphs, curves = augment(data.graphs[:32], data.curves[:32], gen, reflect=0.5, rotate=1.0)
    assert graphs[..., 2:4].abs().max() <= 1 + 1e-6
    batch = LinkageBatch.from_graphs(graphs.numpy())
    result = validate(batch, keep_motion=True, backend="numpy")
    assert result.valid.all()
    paths = torch.as_tensor(result.end_effector_paths(batch))
    centroid, radius = curve_moments(paths, by_arc_length=False)
    paths = (paths - centroid[:, None]) / radius[:, None, None]
    assert chamfer_batch(paths, curves.double()).max() < 1e-4


def test_curve_frame_centres_the_path_and_keeps_the_mechanism():
    s = generate(32, 5)
    graphs = curve_frame(torch.as_tensor(s.graphs), torch.as_tensor(s.centre),
                         torch.as_tensor(s.scale))  # fmt: skip
    valid = graphs[..., 0] > 0.5
    assert (graphs[..., 2:4].norm(dim=-1)[valid] <= FILL + 1e-6).all()
    batch = LinkageBatch.from_graphs(graphs.numpy())
    result = validate(batch, keep_motion=True, backend="numpy")
    assert result.valid.all()
    paths = torch.as_tensor(result.end_effector_paths(batch))
    centroid, radius = curve_moments(paths, by_arc_length=False)
    assert centroid.abs().max() < 1e-5
    assert (radius <= PATH_RADIUS + 1e-6).all() and (radius > PATH_RADIUS - 1e-6).any()
    torch.testing.assert_close(
        (paths - centroid[:, None]) / radius[:, None, None],
        torch.as_tensor(s.curves, dtype=paths.dtype),
        atol=1e-4,
        rtol=0,
    )


def test_epoch_batches_cover_the_data_once_and_group_by_size(data):
    batches = epoch_batches(data.n_nodes, 8, 4, seed=0)
    seen = torch.cat(batches)
    assert len(seen) == len(set(seen.tolist())) == 96
    assert all(len(b) == 8 for b in batches)
    spread = [int(data.n_nodes[b].max() - data.n_nodes[b].min()) for b in batches]
    assert np.mean(spread) < 0.5 * int(data.n_nodes.max() - data.n_nodes.min())
    assert not all(torch.equal(a, b) for a, b in zip(batches, epoch_batches(data.n_nodes, 8, 4, 1)))


def test_learning_rate_warms_up_then_decays_to_the_floor():
    c = replace(PRESETS["cpu"], max_steps=1000, warmup=100)
    lrs = [lr_at(s, c) for s in range(1000)]
    assert lrs[0] < lrs[50] < lrs[99] == pytest.approx(c.lr)
    assert all(a >= b for a, b in itertools.pairwise(lrs[99:]))
    assert lrs[-1] == pytest.approx(c.min_lr, rel=1e-3)


def weights(model) -> torch.Tensor:
    return torch.cat([p.flatten() for p in model.state_dict().values()])


def test_training_is_deterministic_and_resumes_exactly(data, tmp_path):
    straight = train(tiny(tmp_path / "a"), data, data, progress=False)
    again = train(tiny(tmp_path / "b"), data, data, progress=False)
    assert torch.equal(weights(straight), weights(again))
    assert torch.equal(weights(load_checkpoint(tmp_path / "a" / "linkd.pt")[0]), weights(again))
    train(tiny(tmp_path / "c"), data, data, progress=False, stop_at=7)
    resumed = train(tiny(tmp_path / "c"), data, data, progress=False)
    assert torch.equal(weights(resumed), weights(straight))
    other = train(tiny(tmp_path / "d", seed=1), data, data, progress=False)
    assert not torch.equal(weights(other), weights(straight))


def test_loader_workers_prepare_the_same_batches(data, tmp_path):
    inline = train(tiny(tmp_path / "a", sub_mechanisms=0.5), data, data, progress=False)
    ahead = train(tiny(tmp_path / "b", sub_mechanisms=0.5, loader_workers=2), data, data,
                  progress=False)  # fmt: skip
    assert torch.equal(weights(inline), weights(ahead))


def test_training_lowers_the_loss(data, tmp_path):
    torch.manual_seed(0)
    before = LinkD(PRESETS["tiny"].model).eval()
    after = train(tiny(tmp_path, max_steps=100), data, data, progress=False)

    def loss(model):
        torch.manual_seed(0)
        with torch.no_grad():
            return model(data.graphs, conditioning(data.curves), 4)[0].item()

    assert loss(after) < 0.7 * loss(before)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _worker(rank: int, world: int, port: int, config, data) -> None:
    import gc
    import os

    os.environ.update(MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port), RANK=str(rank),
                      WORLD_SIZE=str(world), LOCAL_RANK=str(rank))  # fmt: skip
    import torch.distributed as dist

    # every rank must end with the same weights: gather them on rank 0 and compare there
    flat = weights(train(config, data, data, progress=False))
    gathered = [torch.zeros_like(flat) for _ in range(world)] if rank == 0 else None
    dist.gather(flat, gathered, dst=0)
    if rank == 0:
        torch.save(torch.stack(gathered), f"{config.out}/gathered.pt")
    dist.barrier()  # no rank leaves (closing its sockets) while another still talks to it
    gc.collect()  # free what may still hold the group (a reference cycle) before it goes
    dist.destroy_process_group()


def test_distributed_training_on_two_cpu_processes(data, tmp_path):
    world = 2
    (tmp_path / "r").mkdir()
    config = tiny(tmp_path / "r", max_steps=6, checkpoint_every=3)
    mp.spawn(_worker, args=(world, _free_port(), config, data), nprocs=world, join=True)
    gathered = torch.load(tmp_path / "r" / "gathered.pt")
    assert torch.equal(gathered[0], gathered[1])
    assert torch.equal(weights(load_checkpoint(tmp_path / "r" / "linkd.pt")[0]), gathered[0])


@pytest.mark.parametrize("growth", [{"cross_attention": True}, {"layers": 3}])
def test_warm_start_grows_the_model_without_changing_it(data, tmp_path, growth):
    """Cross-attention (the `cpu-guided` preset) and new blocks (`gpu-deep`) start at zero."""
    from linkd.model import save_checkpoint
    from linkd.train import warm_start

    torch.manual_seed(0)
    plain = LinkD(PRESETS["tiny"].model)
    with torch.no_grad():
        for p in plain.parameters():
            p.add_(0.1 * torch.randn_like(p))  # adaLN away from zero, as after training
    save_checkpoint(tmp_path / "plain.pt", plain.eval())
    grown = LinkD(replace(PRESETS["tiny"].model, **growth)).eval()
    warm_start(grown, tmp_path / "plain.pt")
    graphs, curves = data.graphs[:8], conditioning(data.curves[:8])
    losses = []
    for model in (plain, grown):
        torch.manual_seed(1)
        losses.append(model(graphs, curves)[0].item())
    assert losses[0] == pytest.approx(losses[1], rel=1e-6)
    with pytest.raises(ValueError, match="is"):
        warm_start(LinkD(replace(PRESETS["tiny"].model, dim=48)), tmp_path / "plain.pt")


def test_sub_mechanism_examples_trace_their_curves(data):
    from linkd.evaluate import design_chamfer
    from linkd.training_data import sub_mechanism_examples

    graphs, curves = data.graphs[:32, :19], data.curves[:32]  # cut like a training batch
    g = torch.Generator().manual_seed(0)
    new_graphs, new_curves = sub_mechanism_examples(graphs, curves, g, share=1.0)
    changed = (new_curves - curves).abs().amax((1, 2)) > 1e-6
    assert changed.float().mean() > 0.5  # most graphs have an intermediate coupler joint
    n_old = (graphs[..., VALID] > 0.5).sum(1)
    n_new = (new_graphs[..., VALID] > 0.5).sum(1)
    assert torch.all(n_new[changed] < n_old[changed]) and torch.equal(
        new_graphs[~changed], graphs[~changed]
    )
    # each example is a valid linkage whose last joint traces its (normalised) curve
    distance = design_chamfer(new_graphs.numpy(), new_curves.numpy())
    assert np.all(distance < 1e-3)
    kept = sub_mechanism_examples(graphs, curves, g, share=0.0)
    assert torch.equal(kept[0], graphs) and torch.equal(kept[1], curves)


def test_the_command_line_sets_the_position_weight_of_the_loss(tmp_path):
    from linkd.cli import main
    from linkd.dataset import build

    build(tmp_path / "data", 200, seed=0, shard_size=200)
    out = tmp_path / "run"
    args = ["train", "--preset", "tiny", "--data", str(tmp_path / "data"), "--out", str(out),
            "--steps", "2", "--threads", "1"]  # fmt: skip
    assert main([*args, "--position-weight", "4"]) == 0
    model = load_checkpoint(out / "linkd.pt")[0]
    assert model.config.position_weight == 4.0
    sample = generate(8, 1)
    torch.manual_seed(0)
    curves = conditioning(torch.as_tensor(sample.curves))
    total, parts = model(torch.as_tensor(sample.graphs), curves, 1)
    assert total.item() == pytest.approx(
        sum(v.item() for k, v in parts.items() if k != "position") + 4 * parts["position"].item(),
        rel=1e-5,
    )


def test_the_command_line_offers_every_preset():
    from linkd.commands.train import PRESETS as NAMES

    assert set(NAMES) == set(PRESETS)
