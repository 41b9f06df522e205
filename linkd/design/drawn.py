"""Read a drawn curve the way its author meant it: the target the search works on.

Hand-drawn or digitised input is messy: points crowd where the pen slowed down and thin out
where it sped up, sit on top of each other where it paused, jitter around the stroke, and the
stroke may cross itself. The target is therefore taken by arc length, never by point index
(spacing and repeated points do not matter; a crossing is just two passes through one place,
kept in the order drawn), from a dense resampling filtered at half the target's point spacing,
so that jitter finer than the target can show is averaged, not picked up at random. Optional
smoothing widens that filter for shaky drawings. The curve error of a design is still measured
against the user's own points (`select.curve_error`), never against this target.
"""

from __future__ import annotations

import numpy as np

from linkd.curves import resample

OVERSAMPLE = 16  # dense points per target point


def read_target(points: np.ndarray, count: int, smooth: float = 0.0) -> np.ndarray:
    """(count, 2) points evenly spaced by arc length along the closed curve `points` (P, 2).

    smooth: the standard deviation of the Gaussian the curve is filtered with, as a fraction of
    its length (0: only the anti-aliasing filter, half a target spacing).
    """
    dense_count = count * OVERSAMPLE
    dense = resample(points, dense_count)
    sigma = max(smooth * dense_count, OVERSAMPLE / 2)  # in dense samples
    return resample(_gaussian_closed(dense, sigma), count)


def _gaussian_closed(points: np.ndarray, sigma: float) -> np.ndarray:
    """Points (M, 2) of a closed curve filtered with a circular Gaussian of `sigma` samples."""
    m = len(points)
    frequency = np.fft.fftfreq(m)
    gain = np.exp(-2 * (np.pi * frequency * sigma) ** 2)
    return np.fft.ifft(np.fft.fft(points, axis=0) * gain[:, None], axis=0).real
