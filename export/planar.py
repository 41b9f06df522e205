"""Plane geometry on points written as complex numbers, broadcast over angles: the hull of a
part's joints and the distances between the segments of its outline."""

from __future__ import annotations

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
