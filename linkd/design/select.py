"""Choose among candidates: which to refine, how good a design is, and diverse alternatives.

A design's curve error is the Chamfer distance between its end-effector path and the target,
both resampled to CHAMFER_POINTS points equally spaced by arc length and measured in the
target's normalised frame (centroid and RMS radius of the target's points as given), with no
further alignment: the design has to sit on the user's curve where the user drew it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from linkd.batch import LinkageBatch
from linkd.curves import chamfer, curve_moments, resample
from linkd.geometry import Similarity
from linkd.kinematics import trace
from linkd.mechanism import Mechanism
from linkd.paths import row_angles, stroke_error, timing_error
from linkd.topology import assembly_plan
from linkd.validator import transmission_degrees

CHAMFER_POINTS = 2000
TRACE_ANGLES = 2000  # crank angles a design's path is traced at before resampling


def topology_key(batch: LinkageBatch, row: int) -> bytes:
    """A signature of a candidate's topology (its graph with positions left out)."""
    valid = batch.valid[row]
    n = int(valid.sum())
    return (
        bytes([n])
        + np.packbits(batch.fixed[row, :n]).tobytes()
        + np.packbits(np.triu(batch.adjacency[row, :n, :n], 1)).tobytes()
    )


def diverse_best(batch: LinkageBatch, order: np.ndarray, count: int, per_topology: int) -> list:
    """Up to `count` rows, taken in `order`, with at most `per_topology` of each topology."""
    seen: dict[bytes, int] = {}
    chosen = []
    for row in order:
        key = topology_key(batch, int(row))
        if seen.get(key, 0) < per_topology:
            seen[key] = seen.get(key, 0) + 1
            chosen.append(int(row))
            if len(chosen) == count:
                break
    return chosen


def to_mechanism(
    batch: LinkageBatch,
    row: int,
    frame: Similarity,
    units: str,
    crank_range: tuple[float, float] | None = None,
) -> Mechanism:
    """The candidate `row` as a Mechanism, its positions mapped by `frame` (to the user's)."""
    n = int(batch.valid[row].sum())
    links = tuple(zip(*np.nonzero(np.triu(batch.adjacency[row, :n, :n], 1))))
    positions = frame.apply(batch.positions[row, :n])
    mech = Mechanism(positions, batch.fixed[row, :n], links, (0, 1), batch.end_effector[row], units)
    return mech.replace(crank_range=crank_range)


@dataclass
class Measures:
    """What a designer compares designs by; lengths in the mechanism's units."""

    chamfer: float  # curve error, see the module docstring
    chamfer_200: float  # the same with 200 points on each curve
    nodes: int
    footprint: tuple[float, float]  # width, height of the area the joints sweep
    worst_transmission_deg: float  # the transmission angle closest to 0 or 180, in degrees
    # On an open path: the crank range of the stroke, degrees; the curve errors are then those
    # of the stroke. On a timed path: the timing error (`linkd.paths.timing_error`).
    crank_range_deg: tuple[float, float] | None = None
    timing_error: float | None = None

    def to_dict(self) -> dict:
        figures = {
            "chamfer": self.chamfer,
            "chamfer_200": self.chamfer_200,
            "nodes": self.nodes,
            "footprint": list(self.footprint),
            "worst_transmission_deg": self.worst_transmission_deg,
        }
        if self.crank_range_deg is not None:
            figures["crank_range_deg"] = list(self.crank_range_deg)
        if self.timing_error is not None:
            figures["timing_error"] = self.timing_error
        return figures


def end_effector_path(mech: Mechanism, angles: int | np.ndarray = TRACE_ANGLES) -> tuple:
    """(T, 2) end-effector path, (N, T, 2) all joint paths and the worst sin^2 of a dyad, at
    `angles` crank angles round the revolution or at the crank angles given."""
    batch = LinkageBatch.from_mechanisms([mech])
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    motion = trace(batch.positions, plan, angles)
    paths = motion.paths[0]
    return paths[batch.end_effector[0]], paths, float(motion.margin[0])


def curve_error(path: np.ndarray, target: np.ndarray, points: int = CHAMFER_POINTS) -> float:
    """Chamfer distance of a closed path to the closed target, both resampled to `points` by
    arc length, in the target's normalised frame (its points' centroid and RMS radius)."""
    centre, radius = curve_moments(np.asarray(target, dtype=np.float64), by_arc_length=False)
    a = (resample(path, points) - centre) / radius
    b = (resample(target, points) - centre) / radius
    return chamfer(a, b)


def sampling_floor(target: np.ndarray, starts: int = 8, points: int = CHAMFER_POINTS) -> float:
    """The curve error of the closed target itself, traced finely from `starts` other points
    along it, each a different fraction of the resampling's spacing past one of its points:
    what a design that traces it exactly scores on average, the share of every figure that is
    the resampling's, not the fit's."""
    fine = 64  # finely traced points per resampled one
    dense = resample(target, fine * points)
    k = np.arange(starts)
    shifts = k * len(dense) // starts + ((k + 0.5) * fine / starts).astype(int)
    return float(np.mean([curve_error(np.roll(dense, -s, 0), target, points) for s in shifts]))


def measure(mech: Mechanism, target: np.ndarray, timed: bool = False) -> Measures:
    """Curve error and buildability figures of a design against the target, both in one frame:
    against the stroke of its crank range when it has one, and the timing error when `timed`."""
    path, paths, margin = end_effector_path(mech)
    sweep = paths.reshape(-1, 2)
    extent = sweep.max(0) - sweep.min(0)
    worst = float(transmission_degrees(margin))
    if mech.crank_range is None:
        errors = curve_error(path, target), curve_error(path, target, 200)
        degrees = None
    else:
        stroke = end_effector_path(mech, np.linspace(*mech.crank_range, TRACE_ANGLES))[0]
        errors = stroke_error(stroke, target), stroke_error(stroke, target, 200)
        degrees = tuple(float(np.degrees(v)) for v in mech.crank_range)
    return Measures(
        *errors,
        mech.n_nodes,
        (float(extent[0]), float(extent[1])),
        worst,
        degrees,
        timing_of(mech, target) if timed else None,
    )


def timing_of(mech: Mechanism, rows: np.ndarray, substeps: int = 16) -> float:
    """Timing error of a design for timed rows: on its crank range when it has one, else over
    the revolution at the best phase (searched in steps of 1/substeps of the rows' spacing)."""
    rows = np.asarray(rows, dtype=np.float64)
    n = len(rows)
    if mech.crank_range is not None:
        return timing_error(end_effector_path(mech, row_angles(n, False, mech.crank_range))[0],
                            rows)  # fmt: skip
    path = end_effector_path(mech, n * substeps)[0]
    index = (np.arange(n * substeps)[:, None] + substeps * np.arange(n)) % (n * substeps)
    gaps = np.linalg.norm(path[index] - rows, axis=2).mean(1)  # (phases,)
    best = int(np.argmin(gaps))
    return timing_error(path[index[best]], rows)
