"""Plane geometry on points written as complex numbers, broadcast over angles: the hull of a
part's joints and the distances between the segments of its outline."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def convex_hull(points: np.ndarray) -> list[int]:
    """Indices of the counter-clockwise convex hull of 2D points (collinear points dropped)."""
    order = sorted(range(len(points)), key=lambda k: (points[k][0], points[k][1]))
    points = np.asarray(points)[:, 0] + 1j * np.asarray(points)[:, 1]

    def half(indices: list[int]) -> list[int]:
        chain: list[int] = []
        for k in indices:
            while len(chain) >= 2 and cross(points[chain[-2]], points[chain[-1]], points[k]) <= 0:
                chain.pop()
            chain.append(k)
        return chain

    lower, upper = half(order), half(order[::-1])
    hull = lower[:-1] + upper[:-1]
    return hull or order[:1]


def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z of (a - o) x (b - o) for points as complex numbers, broadcast."""
    return ((a - o).conj() * (b - o)).imag


def point_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from p to segment a-b, points as complex numbers, broadcast."""
    ab, ap = b - a, p - a
    t = np.clip((ap * ab.conj()).real / np.maximum(ab.real**2 + ab.imag**2, 1e-300), 0.0, 1.0)
    return np.abs(ap - t * ab)


def to_segment(p: np.ndarray, _: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Point p's distance to segment a-b in `least_distances`'s form (p: a segment of length 0)."""
    return point_segment(p, a, b)


def segment_distance(a1: np.ndarray, a2: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> np.ndarray:
    """Distance between segments a1-a2 and b1-b2 (complex points, broadcast; 0 if they cross)."""
    d = np.minimum(
        np.minimum(point_segment(a1, b1, b2), point_segment(a2, b1, b2)),
        np.minimum(point_segment(b1, a1, a2), point_segment(b2, a1, a2)),
    )
    crossing = (cross(a1, a2, b1) * cross(a1, a2, b2) < 0) & (
        cross(b1, b2, a1) * cross(b1, b2, a2) < 0
    )
    return np.where(crossing, 0.0, d)


BLOCK = 1 << 16  # segment pairs times coarse angles reckoned at once (memory)


def least_distances(
    a1: np.ndarray,
    a2: np.ndarray,
    b1: np.ndarray,
    b2: np.ndarray,
    distance: Callable = segment_distance,
    symmetric: bool = False,
    rigid: np.ndarray | None = None,
    stride: int = 16,
    below: float | None = None,
) -> np.ndarray:
    """(P, M) least `distance` over the angles between each segment a1-a2 (P, T) and each
    b1-b2 (M, T), cyclic in the angle: `distance(a1[:, None], a2[:, None], b1, b2).min(-1)`,
    reckoned at every `stride`-th angle and then only at the angles between two where the
    segments may come nearer. No point of a segment moves further than its farther-moving
    end, so between two angles the distance falls no lower than the mean of the distances
    there less half the way both segments' ends travel. (Parts pass near each other at a few
    angles of a sweep of thousands.) symmetric: a and b are the same segments. rigid: (P, M)
    pairs that move as one body, whose distance is the same at every angle (the coarse ones
    serve). below: only whether each distance is below it matters, so a pair already nearer
    at a coarse angle is not reckoned further (its figure is then only that angle's)."""
    count = a1.shape[-1]
    coarse = np.arange(0, count, stride)
    length = np.append(np.diff(coarse), count - coarse[-1])
    travel_a, travel_b = _travel(a1, a2, coarse), _travel(b1, b2, coarse)
    least = np.empty((len(a1), len(b1)))
    rows = max(1, BLOCK // max(1, len(b1) * len(coarse)))
    for first in range(0, len(a1), rows):
        p = slice(first, first + rows)
        near = distance(a1[p, None, coarse], a2[p, None, coarse], b1[:, coarse], b2[:, coarse])
        least[p] = near.min(-1)
        travel = travel_a[p, None] + travel_b
        lowest = (near + np.roll(near, -1, axis=-1) - travel) / 2  # within each stretch
        spared = 1e-9 * (np.abs(near) + travel)  # rounding, which the exact values avoid
        maybe = (lowest - spared < least[p, :, None]) & (least[p, :, None] > 0)
        if rigid is not None:
            maybe &= ~rigid[p, :, None]
        if below is not None:
            maybe &= (lowest - spared < below) & (least[p, :, None] >= below)
        if symmetric:  # the pairs below the diagonal are mirrored at the end
            maybe &= (np.arange(first, first + len(near))[:, None] <= np.arange(len(b1)))[..., None]
        k, m, c = np.nonzero(maybe)
        k, m, t = (np.repeat(z, length[c]) for z in (k + first, m, coarse[c]))
        t += np.arange(len(t)) - np.repeat(np.cumsum(length[c]) - length[c], length[c])
        np.minimum.at(least, (k, m), distance(a1[k, t], a2[k, t], b1[m, t], b2[m, t]))
    if symmetric:
        least = np.triu(least) + np.triu(least, 1).T
    return least


def _travel(p: np.ndarray, q: np.ndarray, coarse: np.ndarray) -> np.ndarray:
    """(..., C) the way the farther-travelling end of each segment p-q goes from each coarse
    angle to the next (cyclic)."""
    way = [np.add.reduceat(np.abs(np.roll(z, -1, axis=-1) - z), coarse, axis=-1) for z in (p, q)]
    return np.maximum(*way)
