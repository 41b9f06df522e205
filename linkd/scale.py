"""The sizes linkd can build, checked before any work so extremes fail with one clear line.

Exported parts follow a mechanism's own scale (`linkd.export.options`). Plates under MuJoCo's
mesh volume floor are weighed by their surface, and the distance tolerance of its mesh collisions
follows the parts' gaps (`linkd.export.mjcf`), so generator mechanisms verify down to 0.04 mm
across, but only half of them at 0.02 mm (dynamics and contacts fail): a tenth of a millimetre
keeps a margin. The top size is the largest measured with margin: `linkd verify` failed
mobility at 10 km while its pose solver asked for 1e-12 m; it now asks what the coordinates'
rounding allows (`linkd.verify.pose`), and a 10 km crank rocker verifies, but the range was
not widened on one example. A designed mechanism spans its curve
and usually several times more, so a curve is held to a smaller top size than a mechanism.

Where a mechanism lies matters too: the model is in the user's frame, and double precision
rounds a joint a billion sizes from the origin by a few ten-millionths of its size, which
verification measures (a designed 315 mm mechanism verifies 1e5 km out, 3e8 sizes, and fails
at 3e5 km, 1e9 sizes). Ten million sizes keeps a margin.
"""

from __future__ import annotations

import numpy as np

from linkd.errors import InputError
from linkd.mechanism import UNITS_IN_METRES

MECHANISM_RANGE_M = (1e-4, 1e3)  # across, metres: what export and verification handle
CURVE_RANGE_M = (5e-5, 1e2)  # across, metres: leaves room for the mechanism around the curve
MAX_DISTANCE = 1e7  # farthest point from the origin, in sizes across


def across(points: np.ndarray) -> float:
    """The larger side of the points' bounding box (0 for no points; NaN stays NaN)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return float(np.ptp(points, axis=0).max()) if len(points) else 0.0


def _metres(value: float) -> str:
    """A length in words, to three figures like the size it restates: '1 mm', '100 m', '1 km'."""
    for unit, size in (("km", 1e3), ("m", 1.0), ("mm", 1e-3)):
        if value >= size:
            return f"{value / size:.3g} {unit}"
    return f"{value / 1e-3:.3g} mm"


def size_problem(points: np.ndarray, units: str, what: str, limits: tuple[float, float]) -> str:
    """'' when `points` (in `units`) span a buildable size within MAX_DISTANCE sizes of the
    origin, else the one-line reason."""
    span = across(points)
    size = span * UNITS_IN_METRES[units]
    low, high = limits
    if not low <= size <= high:
        given, metric = f"{span:.3g} {units}", _metres(size) if size else "0"
        return (
            f"the {what} is {given} across{'' if metric == given else f' ({metric})'}; "
            f"linkd builds {what}s from {_metres(low)} to {_metres(high)} across "
            f"(rescale it, or {'set --units' if what == 'curve' else 'change its units'})"
        )
    farthest = float(np.linalg.norm(np.reshape(points, (-1, 2)), axis=1).max())
    if farthest <= MAX_DISTANCE * span:
        return ""
    return (
        f"the {what} lies {farthest:.3g} {units} from the origin, {farthest / span:.3g} times "
        f"its size; linkd builds {what}s within {MAX_DISTANCE:.0e} times their size of the "
        "origin (move it nearer)"
    )


def check_curve_size(points: np.ndarray, units: str, name: str) -> None:
    """InputError naming the curve's size and the buildable range when it lies outside."""
    problem = size_problem(points, units, "curve", CURVE_RANGE_M)
    if problem:
        raise InputError(f"{name}: {problem}")


def check_mechanism_size(points: np.ndarray, units: str, name: str) -> None:
    """InputError naming the mechanism's size and the buildable range when it lies outside."""
    problem = size_problem(points, units, "mechanism", MECHANISM_RANGE_M)
    if problem:
        raise InputError(f"{name}: {problem}")
