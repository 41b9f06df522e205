"""What a target path means: closed (a loop, once per crank revolution) or open (a stroke,
traced once while the crank turns through part of its revolution), and optionally timed (rows
equally spaced in time at constant crank speed).

This module decides open or closed, refuses paths no mechanism should be asked for, and
measures a design against an open or timed target (contract section 1). Closed, untimed
targets are measured by `linkd.design.select.curve_error`.
"""

from __future__ import annotations

import numpy as np

from linkd.curves import COLLINEAR_TOL, MIN_POINTS, chamfer, curve_moments, resample
from linkd.errors import InputError

PATH_KINDS = ("auto", "closed", "open")
OPEN_GAP = 0.05  # an end gap above this fraction of the path's length makes it open ...
OPEN_STEPS = 2.0  # ... and above this many typical steps between rows (a coarse closed loop)
RETRACE_TOL = 1e-9  # relative to the path's length: "exactly" for a path that doubles back


def is_closed(points: np.ndarray) -> bool:
    """Whether a path reads as closed: the gap between its ends is small next to its length
    (below OPEN_GAP of it) or no wider than a couple of its own steps."""
    p = np.asarray(points, dtype=np.float64)
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    steps = steps[steps > 0]
    gap = float(np.linalg.norm(p[-1] - p[0]))
    if len(steps) == 0:
        return True
    return gap <= max(OPEN_GAP * steps.sum(), OPEN_STEPS * float(np.median(steps)))


def checked_path(name: str, points: np.ndarray, kind: str) -> tuple[np.ndarray, bool]:
    """The points of a path read from file `name` and whether it is closed, or an InputError
    saying why it cannot be a target: too few distinct points, a closed path on one line, or a
    path that doubles back on itself exactly (it retraces its whole way back)."""
    if kind not in PATH_KINDS:
        raise InputError(f"--path: expected one of {', '.join(PATH_KINDS)}, got {kind!r}")
    repeats = len(points) > 1 and np.array_equal(points[0], points[-1])
    closed = kind == "closed" or (kind == "auto" and (repeats or is_closed(points)))
    if closed and repeats:
        points = points[:-1]
    distinct = len(np.unique(points, axis=0))
    if distinct == 1 and len(points) > 1:
        raise InputError(f"{name}: all points are equal")
    what = "" if closed else "open path: "
    if distinct < MIN_POINTS:
        raise InputError(f"{name}: {what}{distinct} distinct points, need at least {MIN_POINTS}")
    spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    if closed and spread[1] <= COLLINEAR_TOL * spread[0]:
        raise InputError(f"{name}: all points lie on one line (a closed path needs an area; "
                         "--path open designs a straight stroke)")  # fmt: skip
    if _retraces(points, closed):
        raise InputError(f"{name}: the path doubles back on itself exactly (it retraces its "
                         "whole way back)")  # fmt: skip
    return points, closed


def _retraces(points: np.ndarray, closed: bool, samples: int = 64) -> bool:
    """Whether the path runs out and back along the same track: mirrored in arc length about
    one of its exact turning points (a vertex where it reverses direction), over its whole
    length (an open path turns at half its length and ends where it began)."""
    p = np.vstack([points, points[:1]]) if closed else np.asarray(points)
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    p = p[np.concatenate([[True], step > 0])]
    step = step[step > 0]
    arc = np.concatenate([[0.0], np.cumsum(step)])
    length = arc[-1]
    edges = np.diff(p, axis=0)
    before, after = (np.vstack([edges[-1:], edges]), np.vstack([edges, edges[:1]]))
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    dot = (before * after).sum(1)
    turns = np.flatnonzero((dot < 0) & (np.abs(cross) <= RETRACE_TOL * -dot))
    if not closed:  # no turn at the ends of an open path
        turns = turns[(turns > 0) & (turns < len(edges))]
    turns = turns % len(edges) if closed else turns
    for vertex in turns[:8]:
        centre = arc[vertex]
        if not closed and abs(2 * centre - length) > RETRACE_TOL * length * 1e3:
            continue
        reach = np.linspace(0, length / 2, samples)
        ahead = _point_at(p, arc, centre + reach, closed)
        behind = _point_at(p, arc, centre - reach, closed)
        if np.abs(ahead - behind).max() <= 1e-7 * length:
            return True
    return False


def _point_at(p: np.ndarray, arc: np.ndarray, s: np.ndarray, closed: bool) -> np.ndarray:
    s = np.mod(s, arc[-1]) if closed else np.clip(s, 0, arc[-1])
    return np.stack([np.interp(s, arc, p[:, 0]), np.interp(s, arc, p[:, 1])], axis=1)


def timed_samples(rows: np.ndarray, closed: bool, n: int) -> np.ndarray:
    """(n, 2) points of a timed path at n equally spaced times (linear between rows): for a
    closed path times k/n of the period, for an open one from the first row to the last."""
    rows = np.asarray(rows, dtype=np.float64)
    count = len(rows)
    if closed:
        t = np.arange(n) * count / n
        ext = np.vstack([rows, rows[:1]])
    else:
        t = np.linspace(0, count - 1, n)
        ext = rows
    k = np.arange(len(ext))
    return np.stack([np.interp(t, k, ext[:, 0]), np.interp(t, k, ext[:, 1])], axis=1)


def target_frame(target: np.ndarray) -> tuple[np.ndarray, float]:
    """Centroid and RMS radius of the target's points as given: its normalised frame."""
    centre, radius = curve_moments(np.asarray(target, dtype=np.float64), by_arc_length=False)
    return centre, float(radius)


def stroke_error(stroke: np.ndarray, target: np.ndarray, points: int = 2000) -> float:
    """Chamfer distance of an open traced stroke to an open target, both resampled to `points`
    by arc length (ends included), in the target's normalised frame."""
    centre, radius = target_frame(target)
    a = (resample(stroke, points, closed=False) - centre) / radius
    b = (resample(target, points, closed=False) - centre) / radius
    return chamfer(a, b)


def timing_error(at_times: np.ndarray, rows: np.ndarray) -> float:
    """Mean distance between each row and the end effector at its time (same count and order),
    in the target's normalised frame."""
    radius = target_frame(rows)[1]
    return float(np.linalg.norm(np.asarray(at_times) - rows, axis=1).mean() / radius)


def row_angles(count: int, closed: bool, crank_range: tuple[float, float] | None) -> np.ndarray:
    """Crank angles at which the rows of a timed path are reached (phase 0 for a closed one)."""
    if closed or crank_range is None:
        return 2 * np.pi * np.arange(count) / count
    a, b = crank_range
    return a + (b - a) * np.arange(count) / (count - 1)
