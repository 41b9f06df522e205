"""`linkd design CURVE.csv`: a verified, exported mechanism whose end effector traces the curve.

Exit status: 0 a design was written, 1 no valid design was found (nothing written), 2 bad input.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from linkd.errors import InputError
from linkd.mechanism import DEFAULT_UNITS, UNITS_IN_METRES
from linkd.paths import PATH_KINDS

STRATEGIES = ("node", "graph", "oneshot")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("design", help="design a linkage whose end effector traces a curve")
    p.add_argument("curve", help="target curve: CSV of x,y points along a closed or open path")
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
    # open paths and timing
    p.add_argument("--path", default="auto", help="the curve is a closed loop or an open stroke: "
                   "auto (from the gap between its ends), closed or open")  # fmt: skip
    p.add_argument("--timed", action="store_true",
                   help="the rows are equally spaced in time at constant crank speed")  # fmt: skip
    p.set_defaults(run=run)


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
    if args.path not in PATH_KINDS:
        raise InputError(f"--path: expected one of {', '.join(PATH_KINDS)}, got {args.path!r}")
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
        path=args.path,
        timed=args.timed,
    )
    outcome = design(args.curve, out, options, force=args.force)
    if outcome.design is None:
        print(f"{args.curve}: no valid design found: {outcome.report['reason']}")
        return 1
    d, r = outcome.design, outcome.report
    m = d.measures
    print(f"{out}: {m.nodes}-joint linkage, curve error {m.chamfer:.4f} (Chamfer, normalised), "
          f"{d.export.layers} layers, verified in MuJoCo")  # fmt: skip
    path = r["curve"]["path"] + (" (chosen by --path auto)" if args.path == "auto" else "")
    stroke = ""
    if m.crank_range_deg is not None:
        a, b = m.crank_range_deg
        stroke = f", traced while the crank turns from {a:.1f} to {b:.1f} deg"
    timing = "" if m.timing_error is None else f"; timing error {m.timing_error:.4f} (timed)"
    print(f"  {path} path{stroke}{timing}")
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
