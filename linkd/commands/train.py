"""`linkd train`: train LinkD on generated data (also under torchrun for several processes)."""

from __future__ import annotations

import argparse

PRESETS = ("cpu", "cpu-guided", "cpu-sub", "cpu-canonical", "gpu-sub", "gpu-canonical", "gpu-deep",
           "cuda", "tiny")  # fmt: skip


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train the LinkD model on a generated data set")
    p.add_argument(
        "--preset",
        choices=PRESETS,
        default="cpu",
        help="model size and schedule (default: cpu, about 40 minutes on one CPU core)",
    )
    p.add_argument("--data", default="data/v1", help="data set folder (from `linkd dataset`)")
    p.add_argument("--out", default="runs/linkd", help="run folder: checkpoints and log")
    p.add_argument("--steps", type=int, help="optimiser steps (overrides the preset)")
    p.add_argument("--batch-size", type=int, help="global batch size (overrides the preset)")
    p.add_argument("--lr", type=float, help="peak learning rate (overrides the preset)")
    p.add_argument("--eval-every", type=int, help="steps between validation runs (0: none)")
    p.add_argument(
        "--cross-attention",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="nodes also attend to the curve's patch tokens (default: the preset's)",
    )
    p.add_argument(
        "--position-weight",
        type=float,
        help="weight of the joint-position loss against validity, type and links (default: 2)",
    )
    p.add_argument("--init", help="start from this checkpoint's weights (e.g. a cpu run's)")
    p.add_argument("--seed", type=int, default=0, help="seed of the initial weights and batches")
    p.add_argument("--device", help="cpu or cuda (default: the preset's)")
    p.add_argument(
        "--threads",
        type=int,
        default=0,
        help="torch CPU threads per process (default: torch's choice)",
    )
    p.add_argument(
        "--loader-workers",
        type=int,
        help="processes preparing batches ahead (default: the preset's; 0: none)",
    )
    p.add_argument("--stop-at", type=int, help="pause after this step (resume later)")
    p.add_argument("--no-resume", action="store_true", help="start over even if OUT/last.pt exists")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace
    from pathlib import Path

    from linkd.errors import InputError
    from linkd.train import PRESETS as CONFIGS
    from linkd.train import train

    if args.init and not Path(args.init).is_file():
        raise InputError(f"--init: {args.init}: no such checkpoint")
    if not Path(args.data).is_dir():
        raise InputError(f"{args.data}: no such data folder (make one with `linkd dataset`)")
    overrides = {
        "max_steps": args.steps, "batch_size": args.batch_size, "lr": args.lr,
        "eval_every": args.eval_every, "device": args.device, "init": args.init,
        "loader_workers": args.loader_workers,
    }  # fmt: skip
    preset = CONFIGS[args.preset]
    if args.cross_attention is not None:
        preset = replace(preset, model=replace(preset.model, cross_attention=args.cross_attention))
    if args.position_weight is not None:
        preset = replace(preset, model=replace(preset.model, position_weight=args.position_weight))
    config = replace(
        preset,
        data=args.data,
        out=args.out,
        seed=args.seed,
        threads=args.threads,
        **{k: v for k, v in overrides.items() if v is not None},
    )
    train(config, resume=not args.no_resume, stop_at=args.stop_at)
    final = Path(args.out) / ("linkd.pt" if not args.stop_at else "last.pt")
    print(f"saved: {final}")
    return 0
