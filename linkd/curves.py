"""Target curves: the `curve.csv` reader and writer, arc-length resampling, normalisation,
and the two curve distances linkd ranks designs by (Chamfer and cyclic ordered distance).

A target curve is a closed path given as (M, 2) points in the user's frame and units. Designs
are made in a normalised frame (centroid at the origin, RMS radius 1) and mapped back with the
`Similarity` that `normalise` returns. Alignment of candidate curves lives in `linkd.align`.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from linkd.errors import InputError
from linkd.geometry import Similarity
from linkd.outdir import write_atomic

if TYPE_CHECKING:
    import torch

MIN_POINTS = 8  # distinct points a target curve needs
LARGEST = 1e15  # a coordinate's magnitude, any units: far past what linkd builds or can place
COLLINEAR_TOL = 1e-6  # thickness / length below which the points count as one line
SEPARATORS = (";", ",", "\t", None)  # None: any whitespace; earlier ones win ties
_EXACT = "donot_use_mm_for_euclid_dist"  # torch.cdist: differences, not a matrix product

# Reading and writing


def read_curve(path: str | Path) -> np.ndarray:
    """Read a closed target curve from `path` as (M, 2) float64 points, in file order
    (`read_path` with `kind="closed"`)."""
    return read_path(path, "closed")[0]


def read_path(path: str | Path, kind: str = "auto") -> tuple[np.ndarray, bool]:
    """Read a target path from `path`: its (M, 2) float64 points, in file order, and whether it
    is closed. `kind` is "closed", "open" or "auto" (`linkd.paths.is_closed` decides).

    The separator (semicolon, comma, tab or whitespace) is the one that parses the most rows of
    this file (on a tie, the one that splits the most rows, then the first in SEPARATORS). Except
    with commas as separator, a decimal comma (`1,5`) is accepted. A closing point that
    repeats the first exactly is dropped. Anything the contract refuses raises an `InputError`
    naming the file and, where there is one, the row (line number in the file).
    """
    name = str(path)
    rows = _data_rows(name, path)
    if rows and not any(_number(f, False) is not None for f in re.split(r"[,;\s]+", rows[0][1])):
        rows = rows[1:]  # a header: no field of the first row is a number
    if not rows:
        raise InputError(f"{name}: no points (need at least {MIN_POINTS})")
    sample = [text for _, text in rows[:1000]]
    sep = max(SEPARATORS, key=lambda sep: _fit(sep, sample))
    points = np.empty((len(rows), 2))
    for k, (row, text) in enumerate(rows):
        try:
            points[k] = _parse_row(text, sep)
        except ValueError as exc:
            raise InputError(f"{name}: row {row}: {exc}") from None
    from linkd.paths import checked_path

    return checked_path(name, points, kind)


def write_curve(path: str | Path, points: np.ndarray, comment: str | None = None) -> None:
    """Write points as an `x,y` CSV (atomically), optionally after `# comment` lines."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or not np.isfinite(points).all():
        raise ValueError(f"expected finite (M, 2) points, got shape {points.shape}")
    head = [f"# {line}" for line in comment.splitlines()] if comment else []
    lines = [*head, "x,y", *(f"{float(x)!r},{float(y)!r}" for x, y in points)]
    write_atomic(path, "\n".join(lines) + "\n")


def _data_rows(name: str, path: str | Path) -> list[tuple[int, str]]:
    """(line number, text) of every line left once comments and blank lines are removed."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(f"{name}: cannot read ({exc.strerror or exc})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        row = raw[: exc.start].count(b"\n") + 1
        raise InputError(f"{name}: row {row}: not UTF-8 text") from None
    lines = text.removeprefix("\ufeff").replace("\r\n", "\n").replace("\r", "\n").split("\n")
    stripped = ((k, line.split("#", 1)[0].strip()) for k, line in enumerate(lines, start=1))
    return [(k, line) for k, line in stripped if line]


def _parse_row(text: str, sep: str | None) -> tuple[float, float]:
    """The row's (x, y); a ValueError says what is wrong with it."""
    fields = [f.strip() for f in text.split(sep)]
    while len(fields) > 2 and not fields[-1]:
        fields.pop()  # a trailing separator, as some spreadsheets write
    if len(fields) != 2:
        count = "one column" if len(fields) == 1 else f"{len(fields)} columns"
        raise ValueError(f"{count}, expected two (x, y)")
    values = []
    for field in fields:
        value = _number(field, decimal_comma=sep != ",")
        if value is None:
            raise ValueError(f"{_quote(field)} is not a number")
        if not np.isfinite(value):
            raise ValueError(f"{_quote(field)} is not finite (NaN or inf)")
        if abs(value) > LARGEST:
            raise ValueError(f"{_quote(field)} is too large (linkd reads up to {LARGEST:g})")
        values.append(value)
    return values[0], values[1]


def _fit(sep: str | None, texts: list[str]) -> tuple[int, int]:
    """How well a separator suits the rows: rows it parses, then rows it splits at all."""
    return sum(_parses(t, sep) for t in texts), sum(len(t.split(sep)) > 1 for t in texts)


def _parses(text: str, sep: str | None) -> bool:
    try:
        _parse_row(text, sep)
    except ValueError:
        return False
    return True


def _number(field: str, decimal_comma: bool) -> float | None:
    if decimal_comma and field.count(",") == 1 and "." not in field:
        field = field.replace(",", ".")
    if "_" in field:  # float() accepts 1_000; a curve file should not
        return None
    try:
        return float(field)
    except ValueError:
        return None


def _quote(field: str, limit: int = 24) -> str:
    return repr(field if len(field) <= limit else field[:limit] + "...")


# Resampling and normalisation


def resample(points: np.ndarray, n: int = 200, closed: bool = True) -> np.ndarray:
    """(n, 2) points equally spaced by arc length along the polyline, starting at its first point.

    A closed curve includes the segment from the last point back to the first, and its n points
    do not repeat the first; an open one ends on its last point.
    """
    p = np.asarray(points, dtype=np.float64)
    if closed:
        p = np.vstack([p, p[:1]])
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    p = p[np.concatenate([[True], step > 0])]  # repeated points would stall np.interp
    arc = np.concatenate([[0.0], np.cumsum(step[step > 0])])
    if arc[-1] == 0:
        raise ValueError("cannot resample a curve of zero length")
    s = np.linspace(0.0, arc[-1], n, endpoint=not closed)
    return np.stack([np.interp(s, arc, p[:, 0]), np.interp(s, arc, p[:, 1])], axis=1)


def curve_moments(points, by_arc_length: bool = True):
    """Centroid (..., 2) and RMS radius (...) of closed curves (..., M, 2); numpy or torch.

    By arc length, the curve is a uniform wire: the exact limit of the centroid and RMS radius
    of an arc-length resampling, so they do not depend on how densely each part is sampled.
    Otherwise they are those of the points as given (the benchmark's convention). A curve of
    zero length has its points' mean as centroid and radius 0.
    """
    if not by_arc_length:
        centroid = points.mean(-2)
        return centroid, (((points - centroid[..., None, :]) ** 2).sum(-1).mean(-1)) ** 0.5
    following = points[..., np.roll(np.arange(points.shape[-2]), -1), :]
    length = (((following - points) ** 2).sum(-1)) ** 0.5 + 1e-30  # (..., M) segment lengths
    total = length.sum(-1)
    centroid = (length[..., None] * (points + following)).sum(-2) / (2 * total[..., None])
    a, b = points - centroid[..., None, :], following - centroid[..., None, :]
    second = ((a * a).sum(-1) + (a * b).sum(-1) + (b * b).sum(-1)) / 3  # mean |p|^2 on a segment
    return centroid, ((length * second).sum(-1) / total) ** 0.5


def normalise(points: np.ndarray, by_arc_length: bool = True) -> tuple[np.ndarray, Similarity]:
    """Move a closed curve to centroid 0 and RMS radius 1.

    Returns the normalised points (same order and count) and the `Similarity` that maps the
    normalised frame back to the original one: `sim.apply(normalised)` gives `points` again.
    By default the centroid and radius are those of the curve as a uniform wire (independent of
    the sampling, see `curve_moments`); `by_arc_length=False` uses the points as given, which is
    what "the target's normalised frame" of the benchmark means.
    """
    p = np.asarray(points, dtype=np.float64)
    centroid, radius = curve_moments(p, by_arc_length)
    if not radius > 0:
        raise ValueError("cannot normalise a curve whose points are all equal")
    return (p - centroid) / radius, Similarity(float(radius), np.eye(2), centroid)


# Distances


def chamfer(a: np.ndarray, b: np.ndarray) -> float:
    """Chamfer distance: mean distance from each point of `a` to `b`, plus the same from `b`."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return float(cKDTree(b).query(a)[0].mean() + cKDTree(a).query(b)[0].mean())


def chamfer_batch(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Chamfer distances (B,) of point sets a (B, n, 2) to b (B, m, 2) or one set b (m, 2).

    Differentiable; distances are computed directly (not through a matrix product) so that
    identical sets give exactly zero.
    """
    import torch

    d = torch.cdist(a, b.expand(a.shape[0], *b.shape[-2:]), compute_mode=_EXACT)
    return d.amin(2).mean(1) + d.amin(1).mean(1)


def cyclic_match(
    a: np.ndarray, b: np.ndarray, allow_reverse: bool = True
) -> tuple[int, bool, float]:
    """Best cyclic alignment of two closed curves sampled with the same number of points.

    Returns (shift, reversed, distance): with b' = b[::-1] if reversed else b, the mean of
    |a[i] - b'[(i + shift) % n]| is `distance`, the smallest over all shifts (and directions).
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"curves must have the same shape, got {a.shape} and {b.shape}")
    d = cdist(a, b)
    costs = [_shift_costs_numpy(d)]
    if allow_reverse:
        costs.append(_shift_costs_numpy(d[:, ::-1]))
    costs = np.stack(costs)  # (directions, shifts)
    direction, shift = np.unravel_index(np.argmin(costs), costs.shape)
    return int(shift), bool(direction), float(costs[direction, shift])


def ordered_distance(a: np.ndarray, b: np.ndarray, allow_reverse: bool = True) -> float:
    """Mean point-to-point distance of two equally sampled closed curves, best cyclic shift."""
    return cyclic_match(a, b, allow_reverse)[2]


def ordered_distance_batch(
    a: torch.Tensor, b: torch.Tensor, allow_reverse: bool = True
) -> torch.Tensor:
    """`ordered_distance` for a (B, n, 2) against b (B, n, 2) or (n, 2): (B,), differentiable."""
    import torch

    n = a.shape[-2]
    d = torch.cdist(a, b.expand(a.shape), compute_mode=_EXACT)  # (B, n, n)
    shifted = (torch.arange(n, device=a.device)[:, None] + torch.arange(n, device=a.device)) % n
    index = shifted.expand(a.shape[0], n, n)  # [i, k] -> column (i + k) % n
    costs = d.gather(2, index).mean(1)  # (B, shifts)
    if allow_reverse:
        costs = torch.cat([costs, d.flip(2).gather(2, index).mean(1)], dim=1)
    return costs.amin(1)


def _shift_costs_numpy(d: np.ndarray) -> np.ndarray:
    n = len(d)
    shifted = (np.arange(n)[:, None] + np.arange(n)) % n
    return np.take_along_axis(d, shifted, axis=1).mean(axis=0)
