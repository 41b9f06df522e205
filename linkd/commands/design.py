"""`linkd design CURVE.csv`: a verified, exported mechanism whose end effector traces the curve.

Exit status: 0 a design was written, 1 no valid design was found (nothing written), 2 bad input.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from linkd.errors import InputError
from linkd.mechanism import DEFAULT_UNITS, UNITS_IN_METRES

STRATEGIES = ("node", "graph", "oneshot")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("design", help="design a linkage whose end effector traces a curve")
    p.add_argument("curve", help="target curve: CSV of x,y points along a closed path")
    p.add_argument("--export", default="mjcf,stl", help="formats, comma separated: mjcf, stl")
    p.add_argument("--out", help="output folder (default: <curve>-design, a new name)")
    p.add_argument("--force", action="store_true", help="replace OUT even if it is not an output")
    p.add_argument("--seed", type=int, default=0, help="random seed (runs are repeatable)")
    units = ", ".join(UNITS_IN_METRES)
    p.add_argument("--units", default=DEFAULT_UNITS, help=f"the curve's units: {units}")
    p.add_argument("--strategy", default="node", help="LinkD sampling: node, graph or oneshot")
    p.add_argument("--candidates", type=int, default=512, help="designs to sample")
    p.add_argument("--no-refine", dest="refine", action="store_false",
                   help="deliver the best sample as it is, only placed on the curve")  # fmt: skip
    p.add_argument("--top", type=int, default=0, help="also write alternative topologies")
    p.add_argument("--time-budget", type=float, default=30.0, help="seconds for the whole run")
    p.add_argument("--model", help="LinkD checkpoint (default: the one shipped with linkd)")
    add_search_options(p)
    p.set_defaults(run=run)


def add_search_options(p: argparse.ArgumentParser) -> None:
    """The wider search of drawn shapes (issue 9), shared with `linkd bench design`."""
    p.add_argument("--atlas", default="shipped",
                   help="atlas of mechanisms to look the shape up in: a file from "
                        "`linkd atlas build`, 'shipped' (default) or 'none'")  # fmt: skip
    p.add_argument("--rounds", type=int, default=None,
                   help="refinement rounds, each after the first searching around the best "
                        "designs (default: from the time budget)")  # fmt: skip
    p.add_argument("--smooth", type=float, default=0.0,
                   help="smooth a shaky drawing: Gaussian width as a fraction of the curve's "
                        "length (e.g. 0.005; default 0, the curve as drawn)")  # fmt: skip


def search_options(args: argparse.Namespace) -> dict:
    """DesignOptions fields of the search options, checked (InputError when out of range)."""
    if args.rounds is not None and args.rounds < 1:
        raise InputError(f"--rounds must be at least 1, got {args.rounds}")
    if not 0 <= args.smooth <= 0.1:
        raise InputError(f"--smooth must be between 0 and 0.1, got {args.smooth}")
    if args.atlas not in ("shipped", "none") and not Path(args.atlas).is_file():
        raise InputError(f"--atlas: {args.atlas}: no such file")
    fields = {"atlas": args.atlas != "none", "smooth": args.smooth}
    if args.atlas not in ("shipped", "none"):
        fields["atlas_path"] = args.atlas
    if args.rounds is not None:
        fields["rounds"] = args.rounds
    return fields


def run(args: argparse.Namespace) -> int:
    from linkd.commands.export import parse_formats
    from linkd.design.pipeline import DesignOptions, design
    from linkd.outdir import fresh_name

    formats = parse_formats(args.export)
    if args.units not in UNITS_IN_METRES:
        raise InputError(
            f"--units: expected one of {', '.join(UNITS_IN_METRES)}, got {args.units!r}"
        )
    if args.strategy not in STRATEGIES:
        raise InputError(
            f"--strategy: expected one of {', '.join(STRATEGIES)}, got {args.strategy!r}"
        )
    for name in ("candidates", "top"):
        value = getattr(args, name)
        if value < (1 if name == "candidates" else 0):
            raise InputError(f"--{name} must be at least {1 if name == 'candidates' else 0}")
    if not args.time_budget > 0:
        raise InputError(f"--time-budget must be positive, got {args.time_budget}")
    if args.out:
        out = Path(args.out)
    else:
        base = Path(f"{Path(args.curve).stem}-design")
        out = base if args.force else fresh_name(base)
    single = args.candidates == 1 and not args.refine
    options = DesignOptions(
        candidates=args.candidates,
        strategy=args.strategy,
        refine=args.refine,
        seed=args.seed,
        units=args.units,
        formats=frozenset(formats),
        time_budget=args.time_budget,
        top=args.top,
        rotations=0 if single else DesignOptions.rotations,
        every_joint=not single,
        attempts=1 if single else DesignOptions.attempts,
        model=args.model,
        **search_options(args),
    )
    outcome = design(args.curve, out, options, force=args.force)
    if outcome.design is None:
        print(f"{args.curve}: no valid design found: {outcome.report['reason']}")
        return 1
    d, r = outcome.design, outcome.report
    m = d.measures
    print(f"{out}: {m.nodes}-joint linkage, curve error {m.chamfer:.4f} (Chamfer, normalised), "
          f"{d.export.layers} layers, verified in MuJoCo")  # fmt: skip
    width, height = m.footprint
    print(f"  footprint {width:.4g} x {height:.4g} {args.units}, "
          f"worst transmission angle {m.worst_transmission_deg:.1f} deg")  # fmt: skip
    for alt in outcome.alternatives:
        print(f"  alternative {alt['rank']}: {alt['nodes']} joints, curve error "
              f"{alt['chamfer']:.4f}, {alt['folder']}/")  # fmt: skip
    t = r["timings"]
    parts = ", ".join(f"{k[:-2]} {v:.1f}" for k, v in t.items() if k != "total_s")
    print(f"  {t['total_s']:.1f} s ({parts})")
    return 0
