"""`linkd atlas build`: the atlas of mechanisms that `linkd design` looks shapes up in."""

from __future__ import annotations

import argparse
import time

from linkd.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("atlas", help="build the atlas of mechanisms that design searches")
    actions = p.add_subparsers(dest="action", required=True, parser_class=type(p))
    b = actions.add_parser("build", help="generate random mechanisms and index their paths")
    b.add_argument("--count", type=int, default=300_000, help="random mechanisms to generate")
    b.add_argument("--seed", type=int, default=9, help="random seed (the shipped atlas: 9)")
    b.add_argument("--workers", type=int, default=1, help="processes")
    b.add_argument("--out", help="atlas file (default: the one linkd design uses)")
    b.set_defaults(run=build)


def build(args: argparse.Namespace) -> int:
    from linkd.design.atlas import DEFAULT_PATH
    from linkd.design.atlas import build as build_atlas

    if args.count < 1:
        raise InputError(f"--count must be at least 1, got {args.count}")
    if args.workers < 1:
        raise InputError(f"--workers must be at least 1, got {args.workers}")
    out = args.out or DEFAULT_PATH
    start = time.perf_counter()
    atlas = build_atlas(args.count, args.seed, args.workers)
    atlas.save(out)
    seconds = time.perf_counter() - start
    print(f"{out}: {atlas.meta['mechanisms']:,} mechanisms, {len(atlas):,} paths "
          f"(seed {args.seed}) in {seconds:.1f} s")  # fmt: skip
    return 0
