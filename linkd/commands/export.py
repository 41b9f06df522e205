"""`linkd export M.json --export mjcf,stl --out OUT`: a MuJoCo model and STL parts of a mechanism.

OUT (CONTRACT §4) is built in a staging folder and moved into place only when complete.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from linkd.design.stages import Stages
from linkd.errors import InputError
from linkd.mechanism import Mechanism
from linkd.outdir import fresh_name, staged_output, write_atomic
from linkd.scale import check_mechanism_size

FORMATS = ("mjcf", "stl")
SIZES = {  # each export size option and its default (`linkd.export.options.resolve_sizes`)
    "link_width": "12%% of the mechanism's RMS radius, at most 60%% of the least spacing of "
    "two joints of a part",
    "hole_diameter": "0.4 x the link width",
    "thickness": "0.4 x the link width",
    "layer_gap": "0.1 x the link width",
    "clearance": "0.2 x the link width",
    "density": "1200",
}


EPILOG = """\
The MuJoCo model and the STL parts are in metres whatever the mechanism's units.
Part sizes not given are chosen from the mechanism's size. The model is verified
as `linkd verify` does (report.json "verification"), with a finer time step where
its loops need one. OUT appears only
when complete; an earlier linkd result there is replaced, any other non-empty
folder is refused unless --force.

example:
  linkd export crescent-design/mechanism.json --export mjcf --out crescent-mjcf"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write a MuJoCo model (MJCF) and STL parts of a mechanism",
                       epilog=EPILOG)  # fmt: skip
    p.add_argument("mechanism", help="mechanism.json")
    p.add_argument("--export", default="mjcf,stl", metavar="FORMATS",
                   help="comma separated: mjcf (MuJoCo model), stl (part meshes)")  # fmt: skip
    p.add_argument("--out", help="output folder (default: <mechanism>-export, a name not yet "
                   "taken)")  # fmt: skip
    p.add_argument("--force", action="store_true", help="replace OUT whatever it holds")
    for name, default in SIZES.items():
        unit = "kg/m^3" if name == "density" else "mechanism units"
        flag = "--" + name.replace("_", "-")
        p.add_argument(flag, type=float,
                       help=f"{name.replace('_', ' ')} ({unit}; default: {default})")  # fmt: skip
    p.set_defaults(run=run)


def parse_formats(text: str) -> set[str]:
    formats = {f.strip() for f in text.split(",") if f.strip()}
    unknown = sorted(formats - set(FORMATS))
    if unknown or not formats:
        raise InputError(f"--export: expected a list of {', '.join(FORMATS)}, got {text!r}")
    return formats


def run(args: argparse.Namespace) -> int:
    from linkd.export import ExportOptions, export_mechanism
    from linkd.export.options import resolve_sizes
    from linkd.export.parts import rigid_parts
    from linkd.validator import validate_mechanism
    from linkd.verified import export_verified

    start = time.perf_counter()
    formats = parse_formats(args.export)
    mech = Mechanism.load(args.mechanism)
    check_mechanism_size(mech.positions, mech.units, args.mechanism)
    status, _ = validate_mechanism(mech)
    if status:
        print(f"{args.mechanism}: invalid: {status.reason}", file=sys.stderr)
        return 1
    given = {name: getattr(args, name) for name in SIZES if getattr(args, name) is not None}
    options = ExportOptions(**given)
    try:
        resolve_sizes(mech, rigid_parts(mech), options)
    except ValueError as exc:
        raise InputError(f"{args.mechanism}: {exc}") from None
    out = Path(args.out) if args.out else fresh_name(Path(f"{Path(args.mechanism).stem}-export"))
    stages = Stages()  # on a terminal: what is being tried, as the search can take a minute
    try:
        with staged_output(out, args.force, (Path(args.mechanism),)) as stage:
            begun = time.perf_counter()
            with stages.stage("export", "finding layers for the parts") as note:
                if "mjcf" in formats:  # proved in MuJoCo, which also settles its time step
                    result, verification = export_verified(mech, stage, formats, options,
                                                           stages.progress)  # fmt: skip
                else:
                    result = export_mechanism(mech, stage, formats, options, stages.progress)
                    verification = None
                proof = (
                    ""
                    if verification is None
                    else (", verified in MuJoCo" if verification.passed else ", failed in MuJoCo")
                )
                note(f"{result.layers} layers{proof}")
            timings = {"export_s": result.seconds}
            if verification:
                timings["verify_s"] = time.perf_counter() - begun - result.seconds
            with stages.stage("write", "writing the animation and the plot"):
                timings |= _extras(mech, stage)
            timings["total_s"] = time.perf_counter() - start
            report = _report(result, verification, timings)
            write_atomic(stage / "report.json", json.dumps(report, indent=2))
    except ValueError as exc:
        print(f"{args.mechanism}: cannot export: {exc}", file=sys.stderr)
        return 1
    kinds = ", ".join(f"{n} {kind}" for kind, n in _counts(result.parts).items())
    width = result.sizes["link_width"]
    narrower = (f"; links {width:.3g} {mech.units} wide, {result.narrowed:.2g} of the usual width "
                "(no wider layering found)") if result.narrowed < 1 else ""  # fmt: skip
    disc = result.turntable
    turned = f"; the crank ({disc}) on a turntable: drive it at its rim" if disc else ""
    if result.rings:
        turned += f"; {', '.join(result.rings)} on turntables round the motor's pivot"
    if result.lugged:
        turned += f"; {', '.join(result.lugged)} on ground rings, each held by a lug on a post"
    if result.drive:
        turned += (
            f"; the crank cut in two at the motor's shaft, its halves turned as one by "
            f"{result.drive} and two rods under the base and two over the cover"
        )
    print(f"{out}: {result.layers} layers; parts: {kinds}{narrower}{turned}; "
          f"exported in {result.seconds:.2f} s")  # fmt: skip
    if verification:
        failed = ", ".join(verification.failed)
        print("  verified in MuJoCo" if verification.passed else f"  failed verification: {failed}")
    return 0 if verification is None or verification.passed else 1  # the folder kept to inspect


def _extras(mech: Mechanism, stage: Path) -> dict[str, float]:
    """animation.html (the exported parts when there is a model) and curve.png; their timings."""
    from linkd.verify.animation import parts_from_model, write_animation
    from linkd.verify.plot import write_curve_plot

    start = time.perf_counter()
    model = stage / "mechanism.xml"
    parts = parts_from_model(model, mech) if model.exists() else None
    write_animation(mech, stage / "animation.html", parts=parts)
    middle = time.perf_counter()
    write_curve_plot(mech, stage / "curve.png")
    return {"animation_s": middle - start, "plot_s": time.perf_counter() - middle}


def _counts(parts: list[dict]) -> dict[str, int]:
    """Number of pieces of each kind (ground, link, plate, arm, sheave, pin, post): an arm of a
    split part counts as an arm, not as another link or plate."""
    counts: dict[str, int] = {}
    for part in parts:
        kind = "arm" if "arm_of" in part else part["kind"]
        counts[kind] = counts.get(kind, 0) + 1
    return counts


def _report(result, verification, timings: dict[str, float]) -> dict:
    report = {
        "export": {
            "layers": result.layers,
            "layers_minimal": result.minimal,
            "parts": _counts(result.parts),
            "min_gap": result.min_gap if result.min_gap < float("inf") else None,
            "sizes": result.sizes,
            "files": [str(f) for f in result.files],
        },
    }
    if verification:
        report["verification"] = verification.to_dict()
    return {**report, "timings": timings}
