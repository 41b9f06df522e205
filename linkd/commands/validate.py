"""`linkd validate M.json`: analytic dyadic and branch check (exit 0 valid, 1 invalid)."""

from __future__ import annotations

import argparse

from linkd.errors import InputError
from linkd.mechanism import Mechanism
from linkd.validator import N_ANGLES, validate_mechanism


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check that a mechanism assembles and turns fully")
    p.add_argument("mechanism", help="mechanism.json")
    p.add_argument("--angles", type=int, default=N_ANGLES, help="crank angles to check")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    mech = Mechanism.load(args.mechanism)
    if args.angles < 3:
        raise InputError(f"--angles must be at least 3, got {args.angles}")
    status, margin = validate_mechanism(mech, args.angles)
    if status:
        print(f"{args.mechanism}: invalid: {status.reason}")
        return 1
    print(f"{args.mechanism}: valid ({mech.n_nodes} joints, margin {margin:.4f})")
    return 0
