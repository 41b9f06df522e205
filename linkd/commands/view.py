"""`linkd view OUT`: play the mechanism in a live meshcat viewer; `--html` only writes the page."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import time
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="play an output folder's mechanism in the browser (meshcat)")
    p.add_argument("out", help="output folder holding mechanism.json")
    p.add_argument("--html", action="store_true", help="only write OUT/animation.html")
    p.add_argument(
        "--curve",
        help="target curve CSV to draw beside the traced path (default: the "
        "one OUT/report.json names, if it exists)",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from linkd.mechanism import Mechanism

    out = Path(args.out)
    mech = Mechanism.load(out / "mechanism.json")
    curve = args.curve or _designed_for(out)
    target = None
    if curve:
        from linkd.curves import read_curve

        target = read_curve(curve)
    try:
        if args.html:
            from linkd.verify.animation import write_animation

            write_animation(mech, out / "animation.html", target)
            print(out / "animation.html")
            return 0
        return serve(mech, out, target)
    except ValueError as exc:  # the mechanism does not move through a revolution
        print(f"{out / 'mechanism.json'}: invalid: {exc}", file=sys.stderr)
        return 1


def _designed_for(out: Path) -> str | None:
    """The curve file `linkd design` wrote OUT for, if its report names one that still exists."""
    try:
        curve = json.loads((out / "report.json").read_text())["curve"]["file"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return curve if isinstance(curve, str) and Path(curve).is_file() else None


def serve(mech: object, out: Path, target: object) -> int:
    """Start meshcat's server, send it the scene and keep it playing until Ctrl-C."""
    from types import SimpleNamespace

    from linkd.verify.animation import import_meshcat, model_parts, scene_commands

    commands = scene_commands(mech, target, model_parts(out / "mechanism.xml", mech))
    meshcat = import_meshcat()
    with contextlib.redirect_stdout(io.StringIO()):  # meshcat announces itself; we do below
        viewer = meshcat.Visualizer()
    for command in commands:
        viewer.window.send(SimpleNamespace(lower=lambda command=command: command))
    print(f"meshcat viewer: {viewer.url()}", flush=True)
    print("playing one crank revolution in a loop; Ctrl-C to stop", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        print("stopped")
    return 0
