"""Train LinkD by teacher forcing on generated mechanisms (`linkd train`).

One process, or several under `torchrun` (DistributedDataParallel; gloo on CPU, nccl on CUDA):
each rank takes its share of every global batch. Batches are bucketed by node count so short
graphs do not pay for 20 tokens. Every step's randomness (augmentation, diffusion noise) comes
from seeds derived from (seed, step, rank), so a run is reproducible and resumes exactly.

Conditioning curves are given the form the design pipeline produces: the stored curve (crank
angle samples) is resampled by arc length from a random start, in a random direction, and
normalised. Mechanism and curve are also reflected (and optionally rotated) together. The
mechanisms are trained in their curve's frame (`curve_frame`).
"""

from __future__ import annotations

import copy
import json
import math
import os
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist

from linkd.curves import curve_moments
from linkd.graph import VALID, XY
from linkd.model import LinkD, LinkDConfig, save_checkpoint

N_POINTS = 200
PATH_RADIUS = 0.25  # RMS radius of the end-effector path in the training frame (at most)
FILL = 0.95  # no joint farther than this from the origin in the training frame


@dataclass
class TrainConfig:
    data: str = "data/v1"
    out: str = "runs/linkd"
    model: LinkDConfig = field(default_factory=LinkDConfig)
    batch_size: int = 64  # global batch, split over ranks
    max_steps: int = 10_000
    lr: float = 1e-3
    min_lr: float = 5e-5
    warmup: int = 300
    weight_decay: float = 0.01
    grad_clip: float = 1.0
    ema: float = 0.999
    draws: int = 4  # diffusion timesteps per target node and step
    reflect: float = 0.5  # probability of mirroring mechanism and curve together
    rotate: float = 0.0  # probability of a random rotation of mechanism and curve together
    bucket: int = 50  # batches sorted together by node count
    eval_every: int = 3000
    eval_curves: int = 200
    checkpoint_every: int = 500
    seed: int = 0
    device: str = "cpu"
    bf16: bool = False  # autocast matmuls to bfloat16 (CUDA)
    threads: int = 0  # torch CPU threads per process; 0 keeps torch's default


PRESETS = {
    "cpu": TrainConfig(),
    "cuda": TrainConfig(
        model=LinkDConfig(
            dim=384, layers=8, heads=8, encoder_layers=4, head_widths=(512, 256, 128),
            head_cond=256,
        ),
        batch_size=512, max_steps=150_000, lr=4e-4, min_lr=2e-5, warmup=2000, ema=0.9999,
        draws=4, eval_every=10_000, eval_curves=500, checkpoint_every=2000, device="cuda",
        bf16=True,
    ),
    "tiny": TrainConfig(
        model=LinkDConfig(dim=32, layers=1, heads=2, encoder_layers=1, head_widths=(32, 16),
                          head_cond=16),
        batch_size=16, max_steps=20, warmup=5, eval_every=0, eval_curves=16,
        checkpoint_every=10,
    ),
}  # fmt: skip


@dataclass
class TrainData:
    graphs: torch.Tensor  # (K, 20, 24) float32
    curves: torch.Tensor  # (K, T, 2) float32, crank-angle samples, normalised
    n_nodes: torch.Tensor  # (K,) int64

    def __len__(self) -> int:
        return len(self.graphs)

    @classmethod
    def load(cls, root: str | Path, split: str) -> TrainData:
        """One split of a data set, its mechanisms moved into their curve's frame."""
        from linkd.dataset import load_split

        part = {k: torch.as_tensor(v) for k, v in load_split(root, split).items()}
        graphs = curve_frame(part["graphs"].float(), part["centre"].float(), part["scale"].float())
        return cls(graphs, part["curves"].float(), part["n_nodes"].long())


def curve_frame(graphs: torch.Tensor, centre: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """Mechanisms re-expressed around their end-effector path: its centroid at the origin, its
    RMS radius PATH_RADIUS, or less where a joint would otherwise lie farther out than FILL.

    The target curve is normalised the same way (centroid 0, fixed size), so the model knows
    where the curve lies among the joints it places, instead of guessing the frame.
    """
    valid = graphs[..., VALID] > 0.5
    rel = (graphs[..., XY] - centre[:, None]) / scale[:, None, None]  # in path radii
    reach = (rel.norm(dim=-1) * valid).amax(1)
    k = torch.clamp(FILL / reach, max=PATH_RADIUS)
    out = graphs.clone()
    out[..., XY] = torch.where(valid[..., None], rel * k[:, None, None], 0.0)
    return out


# ---------------------------------------------------------------------------------------------
# Conditioning curves and augmentation


def resample_closed(curves: torch.Tensor, n: int, offset: torch.Tensor) -> torch.Tensor:
    """(B, M, 2) closed polylines -> (B, n, 2) points equally spaced by arc length, starting a
    fraction `offset` (B,) of the length after the first point."""
    following = curves.roll(-1, 1)
    seg = (following - curves).norm(dim=-1)
    start = seg.cumsum(1) - seg
    total = seg.sum(1, keepdim=True)
    s = (offset[:, None] + torch.arange(n, device=curves.device) / n) % 1 * total
    k = (torch.searchsorted(start, s, right=True) - 1).clamp(0, curves.shape[1] - 1)
    frac = ((s - start.gather(1, k)) / seg.gather(1, k).clamp_min(1e-12)).clamp(0, 1)[..., None]
    pick = k[..., None].expand(-1, -1, 2)
    return curves.gather(1, pick) + frac * (following.gather(1, pick) - curves.gather(1, pick))


def conditioning(curves: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """What the model sees: arc-length resampled, normalised curves; with a generator, from a
    random start and in a random direction."""
    b = len(curves)
    if generator is None:
        offset = torch.zeros(b)
    else:
        reverse = torch.rand(b, generator=generator) < 0.5
        curves = torch.where(reverse[:, None, None], curves.flip(1), curves)
        offset = torch.rand(b, generator=generator)
    points = resample_closed(curves, N_POINTS, offset.to(curves.device))
    centroid, radius = curve_moments(points)
    return (points - centroid[:, None]) / radius[:, None, None]


def augment(graphs, curves, generator, reflect: float, rotate: float):
    """Mirror and rotate mechanisms and curves together; positions are shrunk back into
    [-1, 1] if a rotation pushed them out."""
    b = len(graphs)
    angle = torch.rand(b, generator=generator) * 2 * math.pi
    angle = torch.where(torch.rand(b, generator=generator) < rotate, angle, 0.0)
    mirror = torch.where(torch.rand(b, generator=generator) < reflect, -1.0, 1.0)
    cos, sin = angle.cos(), angle.sin()
    rows = [torch.stack([cos * mirror, -sin], -1), torch.stack([sin * mirror, cos], -1)]
    m = torch.stack(rows, -2).to(graphs.device)
    xy = graphs[..., XY] @ m.transpose(1, 2)
    valid = graphs[..., VALID : VALID + 1] > 0.5
    shrink = (xy.abs() * valid).amax((1, 2)).clamp_min(1.0)
    graphs = graphs.clone()
    graphs[..., XY] = torch.where(valid, xy / shrink[:, None, None], 0.0)
    return graphs, curves @ m.transpose(1, 2)


# ---------------------------------------------------------------------------------------------
# Batches


def epoch_batches(n_nodes: torch.Tensor, batch: int, bucket: int, seed: int) -> list[torch.Tensor]:
    """One epoch of global batches: a shuffle, cut into groups of `bucket` batches that are each
    sorted by node count, so a batch holds graphs of similar size; batch order shuffled."""
    g = torch.Generator().manual_seed(seed)
    order = torch.randperm(len(n_nodes), generator=g)
    batches = []
    for start in range(0, len(order) - batch + 1, batch * bucket):
        group = order[start : start + batch * bucket]
        group = group[torch.sort(n_nodes[group], stable=True).indices]
        batches += [group[k : k + batch] for k in range(0, len(group) - batch + 1, batch)]
    perm = torch.randperm(len(batches), generator=g).tolist()
    return [batches[k] for k in perm]


def lr_at(step: int, c: TrainConfig) -> float:
    if step < c.warmup:
        return c.lr * (step + 1) / c.warmup
    progress = min(1.0, (step - c.warmup) / max(1, c.max_steps - c.warmup))
    return c.min_lr + 0.5 * (c.lr - c.min_lr) * (1 + math.cos(math.pi * progress))


def step_seed(c: TrainConfig, step: int, rank: int) -> int:
    return (c.seed * 1_000_003 + step) * 64 + rank


# ---------------------------------------------------------------------------------------------
# Training


def setup_distributed(device: str) -> tuple[int, int, str]:
    """(rank, world size, device); joins the process group when run under torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world == 1:
        return 0, 1, device
    cuda = device.startswith("cuda")
    if not dist.is_initialized():
        dist.init_process_group("nccl" if cuda else "gloo")
    if cuda:
        local = int(os.environ.get("LOCAL_RANK", "0"))
        torch.cuda.set_device(local)
        device = f"cuda:{local}"
    return dist.get_rank(), world, device


def train(
    c: TrainConfig,
    data: TrainData | None = None,
    val: TrainData | None = None,
    resume: bool = True,
    progress: bool = True,
    stop_at: int | None = None,
) -> LinkD:
    """Train (or resume) a run in `c.out`; returns the EMA model, also saved as OUT/linkd.pt.

    stop_at: pause after that many steps (checkpointed, to resume later) without finishing.
    """
    rank, world, device = setup_distributed(c.device)
    if c.batch_size % world:
        raise ValueError(f"batch size {c.batch_size} does not split over {world} processes")
    if c.threads:
        torch.set_num_threads(c.threads)
    out = Path(c.out)
    out.mkdir(parents=True, exist_ok=True)
    data = data if data is not None else TrainData.load(c.data, "train")
    val = val if val is not None else TrainData.load(c.data, "val")

    torch.manual_seed(c.seed)
    model = LinkD(c.model).to(device)
    ema = copy.deepcopy(model).requires_grad_(False)
    decay = [p for p in model.parameters() if p.ndim >= 2]
    no_decay = [p for p in model.parameters() if p.ndim < 2]
    groups = [{"params": decay, "weight_decay": c.weight_decay}, {"params": no_decay}]
    opt = torch.optim.AdamW(groups, lr=c.lr, betas=(0.9, 0.95), weight_decay=0.0)
    step, seconds = 0, 0.0
    last = out / "last.pt"
    if resume and last.exists():
        state = torch.load(last, map_location=device, weights_only=True)
        model.load_state_dict(state["model"])
        ema.load_state_dict(state["ema"])
        opt.load_state_dict(state["optimizer"])
        step, seconds = state["step"], state["seconds"]
    net = model
    if world > 1:
        net = torch.nn.parallel.DistributedDataParallel(model)
    log = Logger(out / "log.jsonl", rank == 0, progress, c.max_steps, step)

    per_epoch = len(epoch_batches(data.n_nodes, c.batch_size, c.bucket, c.seed))
    batches, epoch = [], -1
    started = time.time() - seconds
    end = min(c.max_steps, stop_at or c.max_steps)
    while step < end:
        if step // per_epoch != epoch:
            epoch = step // per_epoch
            batches = epoch_batches(data.n_nodes, c.batch_size, c.bucket, c.seed + epoch)
        index = batches[step % per_epoch][rank::world]
        generator = torch.Generator().manual_seed(step_seed(c, step, rank))
        torch.manual_seed(step_seed(c, step, rank))
        length = min(int(data.n_nodes[index].max()) + 1, data.graphs.shape[1])
        graphs, curves = augment(
            data.graphs[index, :length], data.curves[index], generator, c.reflect, c.rotate
        )
        curves = conditioning(curves, generator)
        with torch.autocast(device.split(":")[0], torch.bfloat16, enabled=c.bf16):
            loss, parts = net(graphs.to(device), curves.to(device), c.draws)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(model.parameters(), c.grad_clip)
        lr = lr_at(step, c)
        for group in opt.param_groups:
            group["lr"] = lr
        opt.step()
        update_ema(ema, model, c.ema, step)
        step += 1
        seconds = time.time() - started
        log.step(step, loss.item(), {k: float(v) for k, v in parts.items()}, lr,
                 float(grad_norm), seconds)  # fmt: skip
        if rank == 0 and (step % c.checkpoint_every == 0 or step == end):
            state = {"model": model.state_dict(), "ema": ema.state_dict(),
                     "optimizer": opt.state_dict(), "step": step, "seconds": seconds}  # fmt: skip
            atomic_save(state, last)
        if rank == 0 and c.eval_every and (step % c.eval_every == 0 or step == c.max_steps):
            log.event(step, seconds, **validation_metrics(ema, val, c))
    final = out / "linkd.pt"
    if rank == 0 and step == c.max_steps:
        meta = {"train": asdict(replace(c, model=asdict(c.model))), "steps": step,
                "seconds": seconds, "world_size": world, "train_size": len(data)}  # fmt: skip
        save_checkpoint(final.with_suffix(".tmp"), ema, meta=meta)
        os.replace(final.with_suffix(".tmp"), final)
    log.close()
    if world > 1:
        dist.barrier()
    return ema.eval()


@torch.no_grad()
def update_ema(ema: LinkD, model: LinkD, decay: float, step: int) -> None:
    decay = min(decay, (1 + step) / (10 + step))
    for e, p in zip(ema.parameters(), model.parameters()):
        e.lerp_(p.detach(), 1 - decay)


def atomic_save(state: dict, path: Path) -> None:
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)


@torch.no_grad()
def validation_metrics(model: LinkD, val: TrainData, c: TrainConfig) -> dict:
    """Teacher-forced loss on validation graphs, and node-level sampling of validation curves:
    the fraction of valid designs and their mean Chamfer distance to the target."""
    from linkd.evaluate import design_chamfer
    from linkd.sample import sample

    model.eval()
    device = next(model.parameters()).device
    torch.manual_seed(c.seed)
    part = slice(0, min(len(val), 1024))
    loss = model(val.graphs[part].to(device), conditioning(val.curves[part]).to(device), c.draws)[0]
    targets = val.curves[: c.eval_curves]
    samples = sample(model, conditioning(targets).numpy(), 1, "node", seed=c.seed)
    chamfer = design_chamfer(samples.graphs, targets.numpy())
    return {
        "val_loss": float(loss),
        "valid": float(samples.valid.mean()),
        "chamfer": float(np.nanmean(chamfer)) if np.isfinite(chamfer).any() else None,
    }


class Logger:
    """Rank 0 writes a JSON line per 50 steps and per evaluation, and drives a rich progress
    bar when stdout is a terminal; evaluations are also printed as one line."""

    def __init__(self, path: Path, enabled: bool, progress: bool, total: int, done: int) -> None:
        self.enabled = enabled
        self.file = open(path, "a") if enabled else None  # noqa: SIM115
        self.sums: dict[str, float] = {}
        self.count = 0
        self.bar = None
        if enabled and progress and sys.stdout.isatty():
            from rich import progress as rp

            self.bar = rp.Progress(
                rp.TextColumn("training"), rp.BarColumn(), rp.MofNCompleteColumn(),
                rp.TextColumn("{task.fields[info]}"), rp.TimeElapsedColumn(),
                rp.TimeRemainingColumn(),
            )  # fmt: skip
            self.task = self.bar.add_task("train", total=total, completed=done, info="")
            self.bar.start()

    def step(self, step, loss, parts, lr, grad_norm, seconds) -> None:
        if not self.enabled:
            return
        for k, v in {"loss": loss, **parts, "grad_norm": grad_norm}.items():
            self.sums[k] = self.sums.get(k, 0.0) + v
        self.count += 1
        if self.bar is not None:
            self.bar.update(self.task, completed=step, info=f"loss {loss:.4f}")
        if step % 50 == 0:
            means = {k: round(v / self.count, 5) for k, v in self.sums.items()}
            self.write({"step": step, "seconds": round(seconds, 1), "lr": lr, **means})
            self.sums, self.count = {}, 0

    def event(self, step: int, seconds: float, **metrics: float) -> None:
        record = {"step": step, "seconds": round(seconds, 1), **metrics}
        self.write(record)
        text = " ".join(f"{k} {v if v is None else round(v, 4)}" for k, v in record.items())
        (self.bar.console.print if self.bar is not None else print)(f"eval: {text}")

    def write(self, record: dict) -> None:
        self.file.write(json.dumps(record) + "\n")
        self.file.flush()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()
        if self.file is not None:
            self.file.close()
