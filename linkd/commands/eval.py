"""`linkd eval`: the paper's evaluation of a LinkD checkpoint: validity and Chamfer per strategy."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("eval", help="success rate and Chamfer distance of LinkD's designs")
    p.add_argument(
        "sources",
        nargs="+",
        help="a data set folder (its test split is used) or a folder of curve CSVs",
    )
    p.add_argument("--checkpoint", help="model checkpoint (default: the shipped one)")
    p.add_argument("--count", type=int, help="use the first N curves of each source")
    p.add_argument("--split", default="test", help="data set split to evaluate (default: test)")
    p.add_argument("--seeds", type=int, default=3, help="independent runs, seeds 0..N-1")
    p.add_argument(
        "--strategies",
        default="oneshot,graph,node,random",
        help="comma-separated subset of oneshot,graph,node and random (the generator's "
        "curve-blind samples, the no-model baseline)",
    )
    p.add_argument("--guidance", type=float, help="guidance scale (default: the model's)")
    p.add_argument("--coins", action=argparse.BooleanOptionalAction, default=None,
                   help="draw validity and type as coins (default: the model's; --no-coins: "
                        "deterministic DDIM, the likelier side)")  # fmt: skip
    p.add_argument("--dyadic", action=argparse.BooleanOptionalAction, default=None,
                   help="decode a joint's links as a dyad's: a moving joint's two likeliest, "
                        "a ground joint's none (default: the model's; --no-dyadic: each link "
                        "on its own)")  # fmt: skip
    p.add_argument("--retries", type=int, default=25,
                   help="tries per node (node level) or per graph (graph level)")  # fmt: skip
    p.add_argument("--steps", type=int, help="DDIM steps (default: the model's)")
    p.add_argument(
        "--speed",
        type=int,
        default=256,
        help="also time node-level sampling of N designs for one curve (0: skip)",
    )
    p.add_argument("--threads", type=int, default=0, help="torch CPU threads (default: torch's)")
    p.add_argument("--out", default="out/eval", help="results folder (one sub-folder per source)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import sys
    from pathlib import Path

    import torch

    from linkd import evaluate as ev
    from linkd.errors import InputError
    from linkd.sample import STRATEGIES, load_model

    strategies = tuple(s.strip() for s in args.strategies.split(",") if s.strip())
    unknown = [s for s in strategies if s not in (*STRATEGIES, ev.BASELINE)]
    if unknown or not strategies:
        raise InputError(f"--strategies: unknown {', '.join(unknown) or '(none given)'}")
    if args.seeds < 1 or (args.count is not None and args.count < 1):
        raise InputError("--seeds and --count must be positive")
    if args.threads:
        torch.set_num_threads(args.threads)
    targets = []
    for source in args.sources:
        folder = Path(source)
        if not folder.is_dir():
            raise InputError(f"{source}: no such folder")
        if any(folder.glob("*.csv")):
            targets.append(ev.folder_targets(folder, args.count))
        else:
            targets.append(ev.dataset_targets(folder, args.split, args.count))
    model = load_model(args.checkpoint)
    if args.guidance is not None:
        model.config.guidance = args.guidance
    if args.coins is not None:
        model.config.sample_coins = args.coins
    if args.dyadic is not None:
        model.config.sample_dyadic = args.dyadic
    progress = sys.stdout.isatty()
    for target in targets:
        results = ev.evaluate(model, target, strategies, tuple(range(args.seeds)), args.retries,
                           args.steps, progress)  # fmt: skip
        results["checkpoint"] = args.checkpoint or "shipped"
        results["guidance"] = model.config.guidance
        results["coins"] = model.config.sample_coins
        results["dyadic"] = model.config.sample_dyadic
        if target.graphs is not None:
            curves = torch.as_tensor(target.conditioning)
            results["conditioning"] = ev.conditioning_gap(model, target.graphs, curves)
        if args.speed > 0:
            results["speed"] = ev.sampling_speed(model, target.conditioning[0], args.speed)
        ev.write_report(results, Path(args.out) / target.name)
        print(ev.table(results))
        if args.speed > 0:
            speed = results["speed"]
            print(f"node-level sampling, one curve: {speed['samples_per_second']} samples/s")
    return 0
