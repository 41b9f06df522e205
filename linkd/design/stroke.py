"""Place candidate mechanisms on an open or timed target: which part of each candidate's
coupler curve (a range of crank angles) matches the target, and by which similarity.

An open target is a stroke: a mechanism traces it while its crank turns through a range
[a, b] of its revolution. A timed target also fixes when each point is reached (rows equally
spaced in time at constant crank speed), so a candidate's path is compared with it point by
point at equal crank-angle steps; a closed timed target spans the whole revolution from some
phase. For every candidate all sub-arcs on a grid of starts and spans are matched at once:
each sub-arc (by arc length, or by equal angle steps when timed) is fitted onto the target
in order by the closed-form best similarity (rotation and uniform scale, plus translation),
in both directions: a path walked backwards is the path of the mirrored mechanism, whose crank
still turns counter-clockwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from linkd.batch import LinkageBatch
from linkd.curves import normalise, resample
from linkd.paths import timed_samples
from linkd.sample import MOVES, spread
from linkd.validator import validate

from .propose import Candidates

PATH_ANGLES = 256  # crank angles each candidate's path is sampled at for the search
STARTS = 32  # sub-arc starts per revolution (open strokes)
PHASES = 64  # phases per revolution (closed timed targets)
SPANS = tuple(np.linspace(0.1, 1.0, 13))  # sub-arc spans, fractions of a revolution
REFINE_STEPS, REFINE_LEVELS = 7, 2  # finer grids: steps per side and how many
MATCH_POINTS = 32  # points per sub-arc and target in the search
ARC_SAMPLES = 1024  # points per revolution, equally spaced by arc length, sub-arcs are read at
SCORE_POINTS = 64  # points per placed stroke when ranking
MAX_REACH = 30.0  # joints placed further than this from the target centroid are penalised
CHUNK = 128  # candidates searched at a time


@dataclass(frozen=True)
class Goal:
    """A target in its normalised frame: `points` (M, 2) equally spaced by arc length (or, when
    timed, in time), `closed` or open, `timed` or not; a drawn loop also `fine`: the same curve
    read at more points, for the last refinement (`polish`)."""

    points: np.ndarray
    closed: bool
    timed: bool
    fine: np.ndarray | None = None

    def samples(self, count: int) -> np.ndarray:
        """(count, 2) points of the target in the same kind of spacing."""
        if self.timed:
            return timed_samples(self.points, self.closed, count)
        return resample(self.points, count, closed=self.closed)

    def loop(self, count: int) -> np.ndarray:
        """A closed curve to sample designs for: the path itself, or the stroke closed by a
        straight return."""
        return resample(self.points, count, closed=True)

    @property
    def stroke(self) -> bool:
        """An open or timed target: designs are placed on it by a crank range too, and scored
        by their stroke's Chamfer distance or their timing error."""
        return not self.closed or self.timed

    @property
    def periodic(self) -> bool:
        """A closed timed target: its samples are reached at phase + 2 pi k / M, k < M."""
        return self.closed and self.timed

    def fractions(self, count: int, like: torch.Tensor) -> torch.Tensor:
        """Where `count` samples lie along a crank range, as fractions of its span."""
        if self.periodic:
            return torch.arange(count, dtype=like.dtype) / count
        return torch.linspace(0, 1, count, dtype=like.dtype)


def make_goal(points: np.ndarray, closed: bool, timed: bool, count: int):
    """The Goal of a path in the user's frame, and the similarity from its frame back."""
    even, frame = normalise(resample(points, count, closed=closed), by_arc_length=closed)
    if not timed:
        return Goal(even, closed, False), frame
    inverse = frame.inverse()
    return Goal(inverse.apply(timed_samples(points, closed, count)), closed, True), frame


def place_stroke(batch: LinkageBatch, goal: Goal, source: np.ndarray | None = None) -> Candidates:
    """Keep the valid linkages of `batch`, place each on the goal by its best sub-arc and
    similarity; returns the candidates, best first, with their crank ranges [a, b] (radians),
    `source` (B,) (default: the proposer's) and, as `chamfer`, their score
    (`stroke_scores`)."""
    result = validate(batch, PATH_ANGLES, keep_motion=True)
    paths = result.end_effector_paths(batch).astype(np.float64)
    keep = np.flatnonzero(result.valid & (spread(paths) > MOVES))
    batch, paths = batch.subset(keep), torch.as_tensor(paths[keep], dtype=torch.float32)
    source = np.zeros(len(keep), int) if source is None else source[keep]
    if len(keep) == 0:
        return Candidates(batch, np.zeros(0), source, ranges=np.zeros((0, 2)))
    target = torch.as_tensor(goal.samples(MATCH_POINTS), dtype=torch.float32)
    joints = torch.as_tensor(batch.positions, dtype=torch.float32)
    found = [_search(paths[c], joints[c], target, goal) for c in _chunks(len(keep))]
    scale, turn, shift, ranges = (torch.cat(parts) for parts in zip(*found))
    scale, ranges = scale.double(), ranges.double()
    turn, shift = turn.to(torch.complex128), shift.to(torch.complex128)
    positions = torch.as_tensor(batch.positions)
    flip = ranges[:, 2] > 0
    z = torch.complex(positions[..., 0], torch.where(flip[:, None], -1, 1) * positions[..., 1])
    placed = scale[:, None] * turn[:, None] * z + shift[:, None]
    batch.positions = torch.stack([placed.real, placed.imag], -1).numpy()
    crank = crank_ranges(ranges[:, 0].numpy(), ranges[:, 1].numpy())
    score = stroke_scores(batch, crank, goal)
    order = np.argsort(score, kind="stable")
    return Candidates(batch.subset(order), score[order], source[order], ranges=crank[order])


def crank_ranges(start: np.ndarray, span: np.ndarray) -> np.ndarray:
    """(K, 2) crank ranges [a, a + span] with each start a wrapped into [0, 2 pi)."""
    a = np.mod(start, 2 * np.pi)
    a = np.where(a < 2 * np.pi, a, 0.0)  # rounding can give 2 pi itself
    return np.stack([a, a + np.minimum(span, 2 * np.pi)], 1)


def _chunks(n: int) -> list[slice]:
    return [slice(k, min(n, k + CHUNK)) for k in range(0, n, CHUNK)]


def _search(paths: torch.Tensor, joints: torch.Tensor, target: torch.Tensor, goal: Goal):
    """Best sub-arc and similarity of each path (B, T, 2) for the target (m, 2): on a grid of
    starts and spans, then on a finer grid around the best of each path.

    Returns scale (B,), rotation as a unit complex number (B,), translation as a complex number
    (B,), and (B, 3) crank start, span (radians, in the placed mechanism) and mirror flag.
    """
    B, T, _ = paths.shape
    m = len(target)
    if goal.periodic:
        starts, spans = torch.arange(PHASES) * (T / PHASES), torch.tensor([float(T)])
    else:
        starts, spans = torch.arange(STARTS) * (T / STARTS), torch.tensor(SPANS) * T
    begin = starts.repeat_interleave(len(spans)).to(paths.dtype).expand(B, -1)  # index units
    length = spans.repeat(len(starts)).to(paths.dtype).expand(B, -1)
    fraction = goal.fractions(m, paths)
    z = torch.complex(target[:, 0], target[:, 1])
    table = None if goal.timed else _arc_table(paths)
    score, gain, centre = _fit(paths, joints, z, begin, length, fraction, table)
    rows = torch.arange(B)
    nudge = torch.linspace(-0.5, 0.5, REFINE_STEPS, dtype=paths.dtype)
    start_step = T / (PHASES if goal.periodic else STARTS)
    span_step = 0.0 if goal.periodic else float(SPANS[1] - SPANS[0]) * T
    for _ in range(REFINE_LEVELS):  # finer grids round the best sub-arc so far
        best = score.amin(1).argmin(1)
        begin = begin[rows, best, None] + start_step * nudge.repeat_interleave(len(nudge))
        length = (length[rows, best, None] + span_step * nudge.repeat(len(nudge))).clamp(1, T)
        score, gain, centre = _fit(paths, joints, z, begin, length, fraction, table)
        start_step, span_step = (step / (REFINE_STEPS - 1) for step in (start_step, span_step))
    best = score.reshape(B, -1).argmin(1)
    mirrored, arc = best // begin.shape[1], best % begin.shape[1]
    gain, centre = gain[rows, mirrored, arc], centre[rows, mirrored, arc]
    shift = z.mean() - gain * centre
    a = begin[rows, arc] * (2 * np.pi / T)
    span = length[rows, arc] * (2 * np.pi / T)
    # The mirrored mechanism starts where the original's last sample is, at minus its angle.
    a = torch.where(mirrored > 0, -(a + span * fraction[-1]), a)
    crank = torch.stack([a, span, mirrored.to(paths.dtype)], 1)
    return gain.abs(), gain / gain.abs().clamp_min(1e-30), shift, crank


def _fit(paths, joints, z, begin, length, fraction, table: tuple | None) -> tuple:
    """Score (B, 2, A), gain (scale and rotation as one complex number) and sub-arc centre of
    every sub-arc [begin, begin + length] (B, A) fitted onto the target z (m,) in order,
    walked forwards and (mirrored) backwards: at equal crank steps when timed (`table` None),
    else at equal arc length (`table`: `_arc_table` of the paths). Each fit needs only the
    sub-arc's sums (of its points, their squares and their products with the target, forwards
    and backwards), so no centred or mirrored copy of the points is made. The sums are taken
    in double precision about each path's mean: a short sub-arc far from it would lose its
    spread's digits in single precision."""
    origin = paths.mean(1, keepdim=True)  # (B, 1, 2)
    if table is None:
        points = _at(paths - origin, begin[..., None] + length[..., None] * fraction)  # (B, A, m)
    else:
        points = _along(table[0], table[1] - origin, begin, length, fraction)
    m, dtype = len(z), z.dtype
    points, z = points.to(torch.complex128), (z - z.mean()).to(torch.complex128)
    mean = points.mean(-1)  # (B, A)
    power = (_square(points).sum(-1) - m * _square(mean)).clamp_min(1e-18)
    # sum of conj(p - mean) z forwards, and of (p - mean) z with the target reversed (mirrored)
    forwards = (points @ z.conj()).conj() - mean.conj() * z.sum()
    backwards = points @ z.flip(0) - mean * z.sum()
    middle = mean + torch.complex(origin[:, 0, 0], origin[:, 0, 1])[:, None]  # in the paths' frame
    scores, gains, centres = [], [], []
    for mirrored, cross in ((False, forwards), (True, backwards)):
        centre = middle.conj() if mirrored else middle
        fit = (_square(z).sum() - _square(cross) / power).clamp_min(0) / m
        gain = cross / power
        # How far the placed joints reach: |gain| times the joints' distance from the centre.
        zj = torch.complex(joints[..., 0], (-1 if mirrored else 1) * joints[..., 1])
        reach = (_square(zj[:, None, :] - centre[..., None]).amax(-1) * _square(gain)).sqrt()
        scores.append(fit.sqrt() + torch.relu(reach - MAX_REACH))
        gains.append(gain)
        centres.append(centre)
    return (
        torch.stack(scores, 1).to(paths.dtype),
        torch.stack(gains, 1).to(dtype),
        torch.stack(centres, 1).to(dtype),
    )


def _square(z: torch.Tensor) -> torch.Tensor:
    """|z|^2 of complex numbers, without the square root of abs()."""
    return z.real**2 + z.imag**2


def _arc_table(paths: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Each closed path (B, T, 2) read by arc length: its arc length at each sample over two
    revolutions (B, 2T + 1), and ARC_SAMPLES points equally spaced by it round one (B,
    ARC_SAMPLES, 2). Sub-arcs are then read from the even points, not searched for in the
    samples one by one."""
    B, T, _ = paths.shape
    step = (paths.roll(-1, 1) - paths).norm(dim=-1)  # (B, T): from sample k to k + 1
    cum = torch.cat([torch.zeros(B, 1, dtype=paths.dtype), step.repeat(1, 2).cumsum(1)], 1)
    want = cum[:, T : T + 1] * (torch.arange(ARC_SAMPLES, dtype=paths.dtype) / ARC_SAMPLES)
    k = torch.searchsorted(cum[:, : T + 1].contiguous(), want, right=True).clamp(1, T)
    lo, hi = cum.gather(1, k - 1), cum.gather(1, k)
    index = (k - 1) + (want - lo) / (hi - lo).clamp_min(1e-18)
    return cum, torch.view_as_real(_at(paths, index[:, None])[:, 0])


def _along(cum: torch.Tensor, even: torch.Tensor, begin: torch.Tensor, length: torch.Tensor,
           fraction: torch.Tensor) -> torch.Tensor:  # fmt: skip
    """(B, A, m) points equally spaced by arc length along each sub-arc [begin, begin + length]
    (index units, wrapping round the revolution) of the paths of `_arc_table` (cum, even)."""
    T = (cum.shape[1] - 1) // 2
    first = _interp_index(cum, begin % T)  # arc length at each sub-arc's start
    last = _interp_index(cum, begin % T + length)
    want = first[..., None] + (last - first)[..., None] * fraction  # (B, A, m)
    return _at(even, want * (ARC_SAMPLES / cum[:, T, None, None].clamp_min(1e-18)))


def _interp_index(values: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """values (B, L) at fractional indices (B, A), linear between samples."""
    low = index.floor().long().clamp(0, values.shape[1] - 2)
    frac = index - low
    return values.gather(1, low) * (1 - frac) + values.gather(1, low + 1) * frac


def _at(paths: torch.Tensor, where: torch.Tensor) -> torch.Tensor:
    """Points of closed paths (B, T, 2) at fractional indices (B, A, m), as complex numbers."""
    B, T, _ = paths.shape
    z = torch.view_as_complex(paths.contiguous())  # (B, T)
    step = z.roll(-1, 1) - z  # from each sample to the next, round the revolution
    low = where.floor()
    frac = (where - low).reshape(B, -1)
    index = low.long().reshape(B, -1) % T
    return (z.gather(1, index) + frac * step.gather(1, index)).reshape(where.shape)


def strokes(batch: LinkageBatch, crank: np.ndarray, goal: Goal, count: int) -> tuple:
    """Each candidate's end effector over its crank range (K, count, 2), at the goal's spacing
    of crank angles, and (K,) whether it turns through it without locking."""
    from linkd.kinematics import trace
    from linkd.topology import assembly_plan

    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    t = goal.fractions(count, torch.zeros((), dtype=torch.float64))
    span = torch.as_tensor(crank[:, 1] - crank[:, 0])
    angles = torch.as_tensor(crank[:, :1]) + span[:, None] * t
    motion = trace(torch.as_tensor(batch.positions), plan, angles)
    rows = torch.arange(len(batch))
    return motion.paths[rows, torch.as_tensor(batch.end_effector)], motion.margin > 0


def stroke_scores(batch: LinkageBatch, crank: np.ndarray, goal: Goal) -> np.ndarray:
    """(K,) how well each candidate's stroke over its crank range matches the goal: the mean
    distance in order when timed, else the Chamfer distance (inf where a candidate locks)."""
    stroke, turns = strokes(batch, crank, goal, SCORE_POINTS)
    target = torch.as_tensor(goal.samples(SCORE_POINTS))
    if goal.timed:
        score = (stroke - target).norm(dim=-1).mean(1)
    else:
        d = torch.cdist(stroke, target[None].expand(len(stroke), -1, -1))
        score = d.amin(2).mean(1) + d.amin(1).mean(1)
    return torch.where(turns, score, torch.inf).numpy()
