"""`linkd trace M.json`: the end effector's path as x,y CSV at crank angles 2*pi*k/N."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from linkd.errors import InputError
from linkd.mechanism import Mechanism
from linkd.validator import N_ANGLES


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("trace", help="write the end effector's path over one crank revolution")
    p.add_argument("mechanism", help="mechanism.json")
    p.add_argument("--angles", type=int, default=N_ANGLES, help="number of crank angles")
    p.add_argument("-o", "--output", help="CSV file to write (default: standard output)")
    p.set_defaults(run=run)


def end_effector_path(mech: Mechanism, n_angles: int) -> np.ndarray:
    """(n_angles, 2) end-effector positions from the assembly pose, crank counter-clockwise."""
    from linkd.batch import LinkageBatch
    from linkd.validator import validate

    batch = LinkageBatch.from_mechanisms([mech])
    result = validate(batch, n_angles, keep_motion=True, backend="numpy")
    if not result.valid[0]:
        from linkd.topology import Status

        raise ValueError(Status(int(result.status[0])).reason)
    return result.end_effector_paths(batch)[0]


def run(args: argparse.Namespace) -> int:
    mech = Mechanism.load(args.mechanism)
    if args.angles < 3:
        raise InputError(f"--angles must be at least 3, got {args.angles}")
    try:
        path = end_effector_path(mech, args.angles)
    except ValueError as exc:
        print(f"{args.mechanism}: invalid: {exc}", file=sys.stderr)
        return 1
    lines = ["x,y", *(f"{x:.9g},{y:.9g}" for x, y in path)]
    text = "\n".join(lines) + "\n"
    if args.output:
        from linkd.outdir import write_atomic

        write_atomic(args.output, text)
    else:
        sys.stdout.write(text)
    return 0
