"""The polish: the best designs of a drawn loop refined once more, at finer crank angles.

The search refines at a few hundred crank angles; the polish takes its best designs on at
1024, against the user's curve read finely (`search._polish_stage` sets it up).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .propose import Candidates
from .select import diverse_best

POLISH_RANGE = 2.0  # a longer budget polishes down the ranking to this many times the best error


def polish(candidates: Candidates, count: int, per_topology: int, refine_finely: Callable,
           progress, until: float | None = None) -> dict:  # fmt: skip
    """Refine the best `count` candidates (at most `per_topology` of a topology) once more, at
    the finer crank angles of `refine_finely`; with `until` (a `time.monotonic()` value), the
    next `count` refined ones after them and so on down the ranking while time remains, as
    far as POLISH_RANGE times the best error. A path traced at a few hundred angles cuts the
    corners where the end effector moves fast, so refinement can settle where the polyline
    fits but the path does not; at finer angles it moves on, and a design ranked lower at the
    coarse angles may end first. A design that misses the hard limits at the finer angles
    keeps its place and error. Returns what it did, for the report (`iterations`: those the
    first designs ran, fewer than asked where the deadline cut them)."""
    order = np.argsort(candidates.chamfer, kind="stable")
    order = order[np.isfinite(candidates.chamfer[order])]
    if until is not None and len(order):
        near = candidates.chamfer[order] <= POLISH_RANGE * candidates.chamfer[order[0]]
        order = order[near & candidates.refined[order]]
    ranking = diverse_best(candidates.batch, order, count if until is None else len(order),
                           per_topology)  # fmt: skip
    if not ranking:
        return {"designs": 0}
    before, done, first = float(candidates.chamfer[ranking[0]]), [], None
    for start in range(0, len(ranking), count):
        rows = np.array(ranking[start : start + count], int)
        errors = candidates.chamfer[rows].copy()
        iterations = refine_finely(candidates, rows, progress)
        first = iterations if first is None else first
        lost = ~np.isfinite(candidates.chamfer[rows])
        candidates.chamfer[rows[lost]] = errors[lost]  # positions are kept where it fails
        done.extend(rows)
        if until is None or time.monotonic() >= until:
            break
    return {"designs": len(done), "before": before,
            "after": float(candidates.chamfer[done].min()), "iterations": first}  # fmt: skip
