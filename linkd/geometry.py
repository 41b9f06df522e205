"""Planar similarity transforms: how designs move between the user's frame and normalised frames.

A similarity maps p -> scale * R @ p + translation, where R is a rotation or a reflection.
Curves are normalised with one (centroid, RMS radius), candidate designs are aligned to the
target with one, and both map back to the user's frame through the inverse.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def rotation(angle: float, reflect: bool = False) -> np.ndarray:
    """2x2 orthogonal matrix: rotation by `angle`, preceded by the reflection y -> -y if asked."""
    c, s = np.cos(angle), np.sin(angle)
    r = np.array([[c, -s], [s, c]])
    return r @ np.diag([1.0, -1.0]) if reflect else r


@dataclass(frozen=True)
class Similarity:
    """p -> scale * rotation @ p + translation (rotation may include a reflection)."""

    scale: float = 1.0
    rotation: np.ndarray = field(default_factory=lambda: np.eye(2))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(2))

    @property
    def reflects(self) -> bool:
        """True when the transform mirrors the plane (this reverses a crank's turning sense)."""
        return bool(np.linalg.det(self.rotation) < 0)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform an array of points of shape (..., 2)."""
        p = np.asarray(points, dtype=np.float64)
        return self.scale * p @ self.rotation.T + self.translation

    def inverse(self) -> Similarity:
        rt = self.rotation.T
        return Similarity(1.0 / self.scale, rt, -(rt @ self.translation) / self.scale)

    def then(self, other: Similarity) -> Similarity:
        """The transform that applies `self` first and `other` second."""
        return Similarity(
            self.scale * other.scale,
            other.rotation @ self.rotation,
            other.scale * other.rotation @ self.translation + other.translation,
        )

    def to_dict(self) -> dict:
        return {
            "scale": float(self.scale),
            "rotation": np.asarray(self.rotation, dtype=float).tolist(),
            "translation": np.asarray(self.translation, dtype=float).tolist(),
        }
