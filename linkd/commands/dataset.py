"""`linkd dataset --count N --out DIR`: random curated mechanisms for training, in shards."""

from __future__ import annotations

import argparse
import os
import time

from linkd.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("dataset", help="generate training data (random curated mechanisms)")
    p.add_argument("--count", type=int, required=True, help="number of mechanisms")
    p.add_argument("--out", required=True, help="data set folder (resumed if it exists)")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes")
    p.add_argument("--seed", type=int, default=0, help="random seed")
    p.add_argument("--shard-size", type=int, default=None, help="mechanisms per shard")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from linkd.dataset import SHARD_SIZE, build

    if args.count < 1:
        raise InputError(f"--count must be at least 1, got {args.count}")
    if args.workers < 1:
        raise InputError(f"--workers must be at least 1, got {args.workers}")
    shard_size = args.shard_size or SHARD_SIZE
    if shard_size < 1:
        raise InputError(f"--shard-size must be at least 1, got {shard_size}")
    start = time.perf_counter()
    manifest, made = build(args.out, args.count, args.seed, args.workers, shard_size)
    seconds = time.perf_counter() - start
    kept = manifest["count"] - made
    rate = f", {made / seconds:,.0f} mechanisms/s" if made else ""
    print(f"{args.out}: {manifest['count']} mechanisms in {len(manifest['shards'])} shards "
          f"({made} made in {seconds:.1f} s{rate}, {kept} kept)")  # fmt: skip
    return 0
