"""`linkd design CURVE.csv`: a verified, exported mechanism whose end effector traces the curve.

Exit status: 0 a design was written, 1 no valid design was found (nothing written), 2 bad input.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from linkd import constraints
from linkd.errors import InputError
from linkd.mechanism import DEFAULT_UNITS, UNITS_IN_METRES
from linkd.paths import PATH_KINDS

STRATEGIES = ("node", "graph", "oneshot")
PROPOSERS = ("model", "random")
PASSED_OVER = {"invalid": "invalid", "unbuildable": "no stack of flat layers builds it",
               "failed_verification": "it failed verification in MuJoCo"}  # fmt: skip

DESCRIPTION = """\
Design a one-degree-of-freedom planar linkage whose end effector traces the
curve in CURVE.csv, prove in MuJoCo that it moves as designed, and write it
to a new folder."""

EPILOG = """\
curve file:
  one "x,y" point per row, in order along the path, in your units (--units);
  a header row, # comments, and comma, semicolon, tab or space separators are
  fine; at least 8 points. A closed path need not repeat its first point.

output folder (OUT), written only when complete (nothing if the run fails):
  mechanism.json   the design, in your frame and units
  mechanism.xml    MuJoCo model (with --export mjcf), in metres whatever --units
  meshes/*.stl     each part as a solid (with --export stl), in metres
  animation.html   one crank revolution, opens offline in a browser
  report.json      curve error, verification figures, timings
  curve.png        your curve, the traced path and the linkage
  Without --out, OUT is <curve>-design in the current folder, or
  <curve>-design-2, -3, ... if that name is taken: nothing is overwritten.
  An OUT given with --out replaces an earlier linkd result there; any other
  non-empty folder is refused. --force replaces OUT (with no --out:
  <curve>-design) whatever it holds.

examples:
  linkd design assets/examples/crescent.csv
  linkd design my_path.csv --units cm --out my-linkage --seed 3 --top 2
  linkd view crescent-design

exit status: 0 a design was written, 1 no valid design was found, 2 bad input."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("design", help="design a linkage whose end effector traces a curve",
                       description=DESCRIPTION, epilog=EPILOG)  # fmt: skip
    p.add_argument("curve", metavar="CURVE.csv",
                   help="target curve: x,y points along a path (see below)")  # fmt: skip
    p.add_argument("--export", default="mjcf,stl", metavar="FORMATS",
                   help="comma separated: mjcf (MuJoCo model), stl (part meshes)")  # fmt: skip
    p.add_argument("--out", help="output folder (default: <curve>-design, a name not yet taken)")
    p.add_argument("--force", action="store_true",
                   help="replace OUT whatever it holds (see below)")  # fmt: skip
    p.add_argument("--seed", type=int, default=0, metavar="S",
                   help="random seed: the same seed gives the same design")  # fmt: skip
    units = ", ".join(UNITS_IN_METRES)
    p.add_argument("--units", default=DEFAULT_UNITS, metavar="UNIT",
                   help=f"unit of the curve's numbers: {units}")  # fmt: skip
    p.add_argument("--strategy", default="node",
                   help="LinkD sampling: node (retry each joint), graph (retry whole designs) "
                   "or oneshot (no retry)")  # fmt: skip
    p.add_argument("--candidates", type=int, default=512, metavar="N",
                   help="designs LinkD samples (more: a closer fit, slower)")  # fmt: skip
    p.add_argument("--no-refine", dest="refine", action="store_false",
                   help="deliver the best sample as it is, only placed on the curve")  # fmt: skip
    p.add_argument("--top", type=int, default=0, metavar="K",
                   help="also write K verified alternatives of other topologies to "
                   "OUT/alternatives/")  # fmt: skip
    p.add_argument("--time-budget", type=float, default=30.0, metavar="SECONDS",
                   help="for the whole run: sampling and refinement stop early to keep it; "
                   "export and verification always finish, and 8 s are kept for them, so a "
                   "budget under about 15 s leaves little or no refinement. A longer one runs "
                   "the 30 s search, then a wider one")  # fmt: skip
    p.add_argument("--model", metavar="CHECKPOINT",
                   help="LinkD checkpoint (default: the one shipped with linkd)")  # fmt: skip
    p.add_argument("--proposer", default="model",
                   help="where candidates come from: model (LinkD) or random (linkd's "
                   "generator, blind to the curve: the baseline)")  # fmt: skip
    constraints.add_arguments(p)
    # open paths and timing
    p.add_argument("--path", default="auto", help="the curve is a closed loop or an open stroke: "
                   "auto (from the gap between its ends), closed or open")  # fmt: skip
    p.add_argument("--timed", action="store_true",
                   help="the rows are equally spaced in time at constant crank speed")  # fmt: skip
    add_search_options(p)
    p.set_defaults(run=run)


def add_search_options(p: argparse.ArgumentParser) -> None:
    """The wider search of drawn shapes (issue 9), shared with `linkd bench design`."""
    p.add_argument("--atlas", default="shipped",
                   help="atlas of mechanisms to look the shape up in: a file from "
                        "`linkd atlas build`, 'shipped' (default) or 'none'")  # fmt: skip
    p.add_argument("--rounds", type=int, default=None,
                   help="refinement rounds, each after the first growing the best designs "
                        "by a joint (default: from the time budget)")  # fmt: skip
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
    if args.proposer not in PROPOSERS:
        raise InputError(
            f"--proposer: expected one of {', '.join(PROPOSERS)}, got {args.proposer!r}"
        )
    for name in ("candidates", "top"):
        value = getattr(args, name)
        if value < (1 if name == "candidates" else 0):
            raise InputError(f"--{name} must be at least {1 if name == 'candidates' else 0}")
    if not 0 < args.time_budget < float("inf"):
        raise InputError(
            f"--time-budget must be a positive number of seconds, got {args.time_budget}"
        )
    if args.path not in PATH_KINDS:
        raise InputError(f"--path: expected one of {', '.join(PATH_KINDS)}, got {args.path!r}")
    if args.out:
        out = Path(args.out)
    else:
        base = Path(f"{Path(args.curve).stem}-design")
        out = base if args.force else fresh_name(base)
    limits = constraints.from_args(args)
    single = args.candidates == 1 and not args.refine
    search = search_options(args)
    if single:  # the model's one sample as it is (CONTRACT §5): no atlas path stands in for it
        search["atlas"] = False
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
        proposer=args.proposer,
        constraints=limits,
        path=args.path,
        timed=args.timed,
        **search,
    )
    outcome = design(args.curve, out, options, force=args.force)
    if outcome.design is None:
        print(f"{args.curve}: no valid design found: {outcome.report['reason']}")
        return 1
    d, r = outcome.design, outcome.report
    m = d.measures
    narrowed = d.export.narrowed
    narrower = f" (links {narrowed:.2g} of the usual width)" if narrowed < 1 else ""
    if d.export.turntable:
        narrower += ", the crank on a turntable (drive it at its rim)"
    if d.export.rings:
        narrower += f", {len(d.export.rings)} more parts on turntables round the motor's pivot"
    if d.export.lugged:
        narrower += f", {len(d.export.lugged)} parts on ground rings held by lugs"
    if d.export.drive:
        narrower += f", the crank cut in two and its halves turned as one by {d.export.drive}"
    print(f"{out}: {m.nodes}-joint linkage, curve error {m.chamfer:.4f} (Chamfer, normalised), "
          f"{d.export.layers} layers{narrower}, verified in MuJoCo")  # fmt: skip
    chosen = " (chosen by --path auto)" if args.path == "auto" else ""
    stroke = ""
    if m.crank_range_deg is not None:
        a, b = m.crank_range_deg
        stroke = f", traced while the crank turns from {a:.1f} to {b:.1f} deg"
    timing = "" if m.timing_error is None else f"; timing error {m.timing_error:.4f} (timed)"
    print(f"  {r['curve']['path']} path{chosen}{stroke}{timing}")
    width, height = m.footprint
    print(f"  footprint {width:.4g} x {height:.4g} {args.units}, "
          f"worst transmission angle {m.worst_transmission_deg:.1f} deg")  # fmt: skip
    best = r["search"].get("best_passed_over")
    if best:  # the accuracy given up, in plain view
        error = f" (curve error {best['chamfer']:.4f})" if "chamfer" in best else ""
        kept = f" ({out / best['folder']}/mechanism.json)" if "folder" in best else ""
        print(f"  a better-ranked design{error} was passed over: {PASSED_OVER[best['reason']]}"
              f"{kept}")  # fmt: skip
    if "constraints" in r:
        print(f"  constraints hold: {constraints.summary(r['constraints'], args.units)}")
    if r["search"].get("budget_cut_refinement"):
        print(f"  the time budget ({args.time_budget:g} s) cut refinement short: a longer "
              "--time-budget may trace your curve closer")  # fmt: skip
    for alt in outcome.alternatives:
        width, height = alt["footprint"]
        print(f"  alternative {alt['rank']}: {alt['nodes']} joints, curve error "
              f"{alt['chamfer']:.4f}, footprint {width:.4g} x {height:.4g} {args.units}, worst "
              f"transmission angle {alt['worst_transmission_deg']:.1f} deg, "
              f"{out / alt['folder']}/")  # fmt: skip
    t = r["timings"]
    parts = ", ".join(f"{k[:-2]} {v:.1f}" for k, v in t.items() if k != "total_s")
    print(f"  {t['total_s']:.1f} s ({parts})")
    return 0
