"""`linkd verify OUT`: headless MuJoCo checks of an export (exit 0 pass, 1 fail, 2 bad input)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "verify",
        help="prove in MuJoCo that an export turns with one degree of freedom, closes its "
        "loops, follows its design and never self-collides",
    )
    p.add_argument("out", help="output folder holding mechanism.json and mechanism.xml")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from rich.console import Console

    from linkd.verify.report import print_report
    from linkd.verify.runner import verify_output

    console = Console()
    if console.is_terminal:
        with console.status("verifying") as status:
            report = verify_output(args.out, progress=lambda step: status.update(step))
    else:
        report = verify_output(args.out)
    print_report(report, console)
    return 0 if report.passed else 1
