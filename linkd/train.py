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

from linkd.model import LinkD, LinkDConfig, save_checkpoint
from linkd.training_data import TrainData, augment, conditioning, sub_mechanism_examples


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
    init: str | None = None  # start from this checkpoint's weights (see `warm_start`)
    sub_mechanisms: float = 0.0  # share of examples replaced by one of their sub-mechanisms
    loader_workers: int = 0  # processes preparing batches ahead (0: the training process)


PRESETS = {
    "cpu": TrainConfig(),
    # Continues a `cpu` run (--init): adds cross-attention to the curve's patches and curve
    # dropout for classifier-free guidance.
    "cpu-guided": TrainConfig(
        model=LinkDConfig(cross_attention=True, curve_dropout=0.1, guidance=1.5),
        max_steps=6000, lr=5e-4, warmup=200, eval_every=2000,
    ),
    # Continues a `cpu-guided` run (--init) with half the examples replaced by sub-mechanisms.
    "cpu-sub": TrainConfig(
        model=LinkDConfig(cross_attention=True, curve_dropout=0.1, guidance=1.5),
        max_steps=14_000, lr=3e-4, warmup=100, eval_every=3500, sub_mechanisms=0.5,
    ),
    # Continues a `cpu-sub` run (--init) in the curve's principal frame (`linkd.model.frame`).
    "cpu-canonical": TrainConfig(
        model=LinkDConfig(cross_attention=True, curve_dropout=0.1, guidance=1.5, canonical=True),
        max_steps=12_000, lr=3e-4, warmup=100, eval_every=3000, sub_mechanisms=0.5,
    ),
    "cuda": TrainConfig(
        model=LinkDConfig(
            dim=384, layers=8, heads=8, encoder_layers=4, head_widths=(512, 256, 128),
            head_cond=256, cross_attention=True, curve_dropout=0.1, guidance=1.5,
        ),
        batch_size=512, max_steps=150_000, lr=4e-4, min_lr=2e-5, warmup=2000, ema=0.9999,
        draws=4, eval_every=10_000, eval_curves=500, checkpoint_every=2000, device="cuda",
        bf16=True,
    ),
    # Continues a `cpu-sub` run (--init) on one GPU: the same model, 16 times the batch, its
    # sub-mechanism examples prepared by loader workers.
    "gpu-sub": TrainConfig(
        model=LinkDConfig(cross_attention=True, curve_dropout=0.1, guidance=1.5),
        batch_size=1024, max_steps=6000, lr=5e-4, min_lr=2e-5, warmup=200, eval_every=0,
        checkpoint_every=1000, device="cuda", sub_mechanisms=0.5, loader_workers=12,
    ),
    # Continues a `gpu-sub` run (--init) at twice the depth: the four new blocks start as the
    # identity (adaLN-Zero gates at zero), so training starts from what the checkpoint computed.
    "gpu-deep": TrainConfig(
        model=LinkDConfig(layers=8, cross_attention=True, curve_dropout=0.1, guidance=1.5),
        batch_size=1024, max_steps=10_000, lr=5e-4, min_lr=2e-5, warmup=200, eval_every=0,
        checkpoint_every=1000, device="cuda", sub_mechanisms=0.5, loader_workers=12,
    ),
    # Continues a `gpu-sub` run (--init) in the curve's principal frame, as `cpu-canonical`.
    "gpu-canonical": TrainConfig(
        model=LinkDConfig(cross_attention=True, curve_dropout=0.1, guidance=1.5, canonical=True),
        batch_size=1024, max_steps=6000, lr=5e-4, min_lr=2e-5, warmup=200, eval_every=0,
        checkpoint_every=1000, device="cuda", sub_mechanisms=0.5, loader_workers=12,
    ),
    "tiny": TrainConfig(
        model=LinkDConfig(dim=32, layers=1, heads=2, encoder_layers=1, head_widths=(32, 16),
                          head_cond=16),
        batch_size=16, max_steps=20, warmup=5, eval_every=0, eval_curves=16,
        checkpoint_every=10,
    ),
}  # fmt: skip


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


class StepBatches(torch.utils.data.Dataset):
    """Item `step` is that step's prepared batch (this rank's share): its graphs and curves
    after sub-mechanisms, augmentation and resampling. It depends on the step alone, so a
    run is the same whether the training process prepares it or loader workers do (on a
    GPU the sub-mechanisms' kinematics, on the CPU, would otherwise starve the device)."""

    def __init__(self, data: TrainData, c: TrainConfig, rank: int, world: int) -> None:
        self.data, self.c, self.rank, self.world = data, c, rank, world
        self.per_epoch = len(epoch_batches(data.n_nodes, c.batch_size, c.bucket, c.seed))
        self.epoch, self.batches = -1, []

    def __len__(self) -> int:
        return self.c.max_steps

    def __getitem__(self, step: int) -> tuple[torch.Tensor, torch.Tensor]:
        c, data = self.c, self.data
        if step // self.per_epoch != self.epoch:
            self.epoch = step // self.per_epoch
            self.batches = epoch_batches(data.n_nodes, c.batch_size, c.bucket, c.seed + self.epoch)
        index = self.batches[step % self.per_epoch][self.rank :: self.world]
        generator = torch.Generator().manual_seed(step_seed(c, step, self.rank))
        length = min(int(data.n_nodes[index].max()) + 1, data.graphs.shape[1])
        graphs, curves = data.graphs[index, :length], data.curves[index]
        if c.sub_mechanisms > 0:
            graphs, curves = sub_mechanism_examples(graphs, curves, generator, c.sub_mechanisms)
        graphs, curves = augment(graphs, curves, generator, c.reflect, c.rotate)
        return graphs, conditioning(curves, generator)


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
    if c.init:
        warm_start(model, c.init)
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

    end = min(c.max_steps, stop_at or c.max_steps)
    loader = torch.utils.data.DataLoader(
        StepBatches(data, c, rank, world), batch_size=None, sampler=range(step, end),
        num_workers=c.loader_workers, prefetch_factor=4 if c.loader_workers else None,
        pin_memory=device.startswith("cuda"),
    )  # fmt: skip
    started = time.time() - seconds
    for graphs, curves in loader:
        torch.manual_seed(step_seed(c, step, rank))
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
def warm_start(model: LinkD, path: str | Path) -> None:
    """Copy a checkpoint's weights into `model`, which may have grown since: parameters it
    lacks keep their initialisation, and a layer that got wider (the adaLN projection, when
    cross-attention is added) takes the old rows first. New adaLN rows start at zero, so the
    warm-started model computes exactly what the checkpoint did until training moves it."""
    old = torch.load(Path(path), map_location="cpu", weights_only=True)["model"]
    state = model.state_dict()
    for name, value in old.items():
        if name not in state:
            raise ValueError(f"{path}: {name} has no place in this model")
        target = state[name]
        if target.shape[1:] != value.shape[1:] or target.shape[0] < value.shape[0]:
            raise ValueError(f"{path}: {name} is {tuple(value.shape)}, here {tuple(target.shape)}")
        target[: value.shape[0]] = value
    model.load_state_dict(state)


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
    """Teacher-forced loss on validation graphs with their own and with shuffled curves (the
    gap is what the model takes from the curve), and node-level sampling of validation curves:
    the fraction of valid designs and their mean Chamfer distance to the target."""
    from linkd.evaluate import conditioning_gap, design_chamfer
    from linkd.sample import sample

    model.eval()
    device = next(model.parameters()).device
    part = slice(0, min(len(val), 1024))
    curves = conditioning(val.curves[part]).to(device)
    gap = conditioning_gap(model, val.graphs[part].to(device), curves, c.seed, c.draws)
    targets = val.curves[: c.eval_curves]
    samples = sample(model, conditioning(targets).numpy(), 1, "node", seed=c.seed)
    chamfer = design_chamfer(samples.graphs, targets.numpy())
    return {
        "val_loss": gap["own"]["loss"],
        "shuffled_loss": gap["shuffled"]["loss"],
        "conditioning_gap": gap["gap"]["loss"],
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
