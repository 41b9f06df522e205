"""`linkd validate M.json`: analytic dyadic and branch check (exit 0 valid, 1 invalid), and the
designer's constraints when given (exit 1 naming what is violated)."""

from __future__ import annotations

import argparse

from linkd import constraints
from linkd.errors import InputError
from linkd.mechanism import Mechanism
from linkd.validator import N_ANGLES, transmission_degrees, validate_mechanism


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check that a mechanism assembles and turns fully")
    p.add_argument("mechanism", help="mechanism.json")
    p.add_argument("--angles", type=int, default=N_ANGLES, help="crank angles to check")
    constraints.add_arguments(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    mech = Mechanism.load(args.mechanism)
    if args.angles < 3:
        raise InputError(f"--angles must be at least 3, got {args.angles}")
    limits = constraints.from_args(args)
    status, margin = validate_mechanism(mech, args.angles)
    if status:
        print(f"{args.mechanism}: invalid: {status.reason}")
        return 1
    if limits:
        measured = constraints.check(mech, limits)
        unmet = [m for m in measured if not m.holds]
        if unmet:
            what = "; ".join(f"{constraints.option(m.name)}: {constraints.describe(m, mech.units)}"
                             for m in unmet)  # fmt: skip
            print(f"{args.mechanism}: violates {what}")
            return 1
        held = constraints.summary([m.to_dict() for m in measured], mech.units)
        print(f"{args.mechanism}: valid ({mech.n_nodes} joints, {_worst(margin)}); "
              f"constraints hold: {held}")  # fmt: skip
        return 0
    print(f"{args.mechanism}: valid ({mech.n_nodes} joints, {_worst(margin)})")
    return 0


def _worst(margin: float) -> str:
    """The validator's margin in words."""
    return f"worst transmission angle {transmission_degrees(margin):.1f} deg"
