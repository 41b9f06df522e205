"""Polylines at the resolution a screen shows: a user's curve may have a million points, the page
or plot that draws it needs a few thousand. Only drawings use this; measures use every point."""

from __future__ import annotations

import numpy as np

PIXELS = 4096  # grid cells across the curve's extent: a 4K screen, the curve filling its width
MAX_POINTS = 20_000  # at most this many points are kept, however the curve wanders


def screen_polyline(points: np.ndarray, pixels: int = PIXELS) -> np.ndarray:
    """The points (n, 2) of a polyline, thinned for drawing: of consecutive points that fall in
    one cell of a `pixels` x `pixels` grid over the polyline's extent, only the first is kept
    (and always the last point), so every dropped point is within a cell's diagonal of a kept
    one. A curve that still has more than MAX_POINTS points (noise that crosses cells back and
    forth) is thinned further to MAX_POINTS points evenly spread along its order."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) < 3:
        return points
    low = points.min(axis=0)
    cell = max(float(np.ptp(points, axis=0).max()), 1e-300) / pixels
    cells = np.floor((points - low) / cell).astype(np.int64)
    keep = np.ones(len(points), dtype=bool)
    keep[1:-1] = (cells[1:-1] != cells[:-2]).any(axis=1)
    kept = points[keep]
    if len(kept) > MAX_POINTS:
        kept = kept[np.linspace(0, len(kept) - 1, MAX_POINTS).round().astype(np.int64)]
    return kept
