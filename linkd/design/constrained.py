"""The design search under a designer's constraints (`linkd.constraints`), so that what reaches
the final check already meets them and stays accurate.

Everything here works in the target's normalised frame, on constraints mapped into it:
- `pin`: with a motor point, each placed candidate is moved by the similarity that best fits its
  path to the target among those that map its crank pivot exactly onto the motor point (the
  translation follows from rotation and scale, which stay free, fitted by ICP about the point;
  `pin_stroke` the same for an open or timed path, over each candidate's crank range); with a
  ground box but no motor point, those whose crank pivot is outside it at the box's nearest
  point (`pinned`);
- `rank`: candidates that nearly meet the constraints already go first, so they are refined;
- `Barriers`: refinement terms keeping fixed joints in the ground box and every joint in the
  envelope over the cycle (soft quadratic penalties, with hard limits on the kept iterate), and
  `tightened`: refinement settings raised to the shortest link and transmission angle asked for.
  The pinned crank pivot is not moved by refinement at all (its gradient is zero).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from functools import partial, reduce

import numpy as np
import torch

from linkd.batch import LinkageBatch
from linkd.constraints import ROUNDING, Constraints, measure_batch
from linkd.curves import chamfer_batch
from linkd.geometry import Similarity
from linkd.validator import validate

from .parallel import run_parts, split
from .propose import Candidates, merged
from .refine import RefineSettings, resample_closed
from .stroke import Goal, stroke_scores, strokes

# Inner margins (normalised units, the target's RMS radius is 1) for the ground box and the
# envelope: the iterate refinement keeps must stay HARD inside; the penalty pushes towards SOFT.
HARD, SOFT = 0.005, 0.04
EXTRA_DEGREES = (0.5, 4.0)  # the same for the transmission angle: hard and soft, over the limit
LINK_FACTOR = 1.02  # hard limit on link length, times the shortest allowed
PIN_POINTS, PIN_STEPS = 64, 10  # points per curve and ICP steps of the pinned fit
RANK_WEIGHT = 0.5  # weight of the constraint violation beside the Chamfer distance in `rank`


def pinned(candidates: Candidates, c: Constraints, pin_at: Callable) -> Candidates:
    """Placed candidates as the constraints pin them (`pin_at(candidates, motor=points)`: `pin`
    or `pin_stroke`, onto (B, 2) points): with a motor point, each crank pivot moved onto it;
    with a ground box alone, each pivot outside the box (or within SOFT of its sides) moved to
    the nearest point SOFT inside it, so that refinement starts with the pivot where it may
    stay (pulled in by the barrier alone, it bends the path away: on LInK-Bench random/006 with
    the box alone, 0.10 against 0.002 to 0.02); else as they are."""
    if len(candidates) == 0 or (c.motor_at is None and c.ground_box is None):
        return candidates
    if c.motor_at is not None:
        return pin_at(
            candidates, motor=np.tile(np.asarray(c.motor_at, float), (len(candidates), 1))
        )
    pivots = candidates.batch.positions[:, 0]
    box = c.ground_box
    corners = np.array([[box.x0, box.y0], [box.x1, box.y1]])
    middle = corners.mean(0)  # a box under 2 SOFT across pins at its middle
    inside = np.clip(pivots, np.minimum(corners[0] + SOFT, middle),
                     np.maximum(corners[1] - SOFT, middle))  # fmt: skip
    out = (inside != pivots).any(1)
    if not out.any():
        return candidates
    rows = np.flatnonzero(out)
    moved = pin_at(candidates.subset(rows), motor=inside[rows])
    return merged(candidates.subset(np.flatnonzero(~out)), moved)


def pin(candidates: Candidates, target: np.ndarray, motor: np.ndarray) -> Candidates:
    """Re-place placed candidates so that each crank pivot lies exactly on its motor point
    (`motor`: (B, 2)), with the rotation and scale about it that fit the path best, in two
    parts at once (`parallel`, as `place` is); sorted by the new Chamfer distance."""
    if len(candidates) == 0:
        return candidates
    parts = split(np.arange(len(candidates)))
    calls = [partial(_pin, candidates.subset(part), target, motor[part]) for part in parts]
    both = reduce(merged, run_parts(calls))
    return both.subset(np.lexsort((np.concatenate(parts), both.chamfer)))  # ties as given


def _pin(candidates: Candidates, target: np.ndarray, motor: np.ndarray) -> Candidates:
    """`pin` in one process, unsorted."""
    batch = candidates.batch
    result = validate(batch, keep_motion=True)
    paths = torch.as_tensor(result.end_effector_paths(batch), dtype=torch.float64)
    pivot = torch.as_tensor(batch.positions[:, 0])
    goal = (
        torch.as_tensor(target, dtype=torch.float64)[None] - torch.as_tensor(motor)[:, None]
    )  # (B, n, 2): about each motor point
    even = resample_closed(paths, len(target)) - pivot[:, None]  # about the pivot
    every = max(1, len(target) // PIN_POINTS)
    u, v = even[:, ::every].float(), goal[:, ::every].float()
    factor = torch.zeros(len(batch), 2)
    factor[:, 0] = 1  # (scale cos, scale sin): a pure translation to begin with
    for _ in range(PIN_STEPS):
        factor = _fit_about_origin(u, v, factor)
    factor = factor.double()
    chamfer = _chamfer(_turn(even, factor), goal)
    placed = _about(batch, factor, motor)
    return Candidates(placed, np.nan_to_num(chamfer.numpy(), nan=np.inf), candidates.source)


def pin_stroke(candidates: Candidates, goal: Goal, motor: np.ndarray) -> Candidates:
    """`pin` for placed strokes: the scale and rotation about the motor points that best map
    each end effector's path over its crank range onto the goal, point to point in order (least
    squares, in closed form), then on a path not timed by ICP; sorted by the new score."""
    batch = candidates.batch
    if len(batch) == 0:
        return candidates
    paths, _ = strokes(batch, candidates.ranges, goal, PIN_POINTS)
    pivot = torch.as_tensor(batch.positions[:, 0])
    goal_points = torch.as_tensor(goal.samples(PIN_POINTS))[None] - torch.as_tensor(motor)[:, None]
    u = torch.view_as_complex((paths - pivot[:, None]).contiguous())
    v = torch.view_as_complex(goal_points.contiguous())
    z = (u.conj() * v).sum(1) / (u.abs() ** 2).sum(1)
    factor = torch.nan_to_num(torch.view_as_real(z)).float()
    if not goal.timed:  # the path's points need not be reached in order: nearest points
        for _ in range(PIN_STEPS):
            factor = _fit_about_origin(torch.view_as_real(u).float(), goal_points.float(), factor)
    placed = _about(batch, factor.double(), motor)
    score = stroke_scores(placed, candidates.ranges, goal)
    order = np.argsort(score, kind="stable")
    return Candidates(placed.subset(order), score[order], candidates.source[order],
                      ranges=candidates.ranges[order])  # fmt: skip


def _about(batch: LinkageBatch, factor: torch.Tensor, motor: np.ndarray) -> LinkageBatch:
    """The linkages scaled and turned about their crank pivots by `factor` (B, 2), each pivot
    then exactly on its motor point (`motor`: (B, 2))."""
    rel = torch.as_tensor(batch.positions - batch.positions[:, :1])
    moved = _turn(rel, factor).numpy() + motor[:, None]
    moved[:, 0] = motor  # exactly
    return LinkageBatch(moved, batch.fixed, batch.valid, batch.adjacency, batch.end_effector)


def _turn(points: torch.Tensor, factor: torch.Tensor) -> torch.Tensor:
    """Points (B, n, 2) scaled and turned about the origin by factor (B, 2) = s cos, s sin."""
    c, s = factor[:, None, 0], factor[:, None, 1]
    x, y = points[..., 0], points[..., 1]
    return torch.stack([c * x - s * y, s * x + c * y], -1)


def _fit_about_origin(u: torch.Tensor, v: torch.Tensor, factor: torch.Tensor) -> torch.Tensor:
    """One ICP step: the scale and rotation about the origin, as (s cos, s sin) (B, 2), that
    best map the points u (B, k, 2) onto v (B, m, 2) when each point is paired with its nearest
    on the other curve, both ways (least squares, in closed form)."""
    d = torch.cdist(_turn(u, factor), v)  # (B, k, m); min's indices: argmin's, found sooner
    to_v = v.gather(1, d.min(2).indices[..., None].expand(-1, -1, 2))  # (B, k, 2) u's partners
    to_u = u.gather(1, d.min(1).indices[..., None].expand(-1, -1, 2))  # (B, m, 2) of v's points
    src, dst = torch.cat([u, to_u], 1), torch.cat([to_v, v], 1)
    dot = (src * dst).sum((1, 2))
    cross = (src[..., 0] * dst[..., 1] - src[..., 1] * dst[..., 0]).sum(1)
    new = torch.stack([dot, cross], 1) / (src**2).sum((1, 2)).clamp_min(1e-30)[:, None]
    return torch.where(torch.isfinite(new).all(1, keepdim=True), new, factor)


def _chamfer(a: torch.Tensor, b: torch.Tensor, chunk: int = 64) -> torch.Tensor:
    """(B,) Chamfer distance of a (B, n, 2) to b (B, m, 2), in chunks that bound the memory."""
    return torch.cat([chamfer_batch(p, q) for p, q in zip(a.split(chunk), b.split(chunk))])


def violation(batch: LinkageBatch, c: Constraints) -> np.ndarray:
    """(B,) how far each linkage is from meeting the constraints, summed: lengths in the
    batch's units, transmission angles in units of 30 degrees."""
    total = np.zeros(len(batch))
    for name, (_, margin) in measure_batch(batch, c, 128).items():
        scale = 30.0 if name == "min_transmission" else 1.0
        if name != "max_joints":
            total += np.maximum(-np.nan_to_num(margin, nan=-1.0), 0) / scale
    return total


def rank(candidates: Candidates, c: Constraints) -> Candidates:
    """Candidates sorted by Chamfer distance plus RANK_WEIGHT times their violation."""
    if len(candidates) == 0:
        return candidates
    score = candidates.chamfer + RANK_WEIGHT * violation(candidates.batch, c)
    order = np.argsort(score, kind="stable")
    return candidates.subset(order)


def tightened(settings: RefineSettings, c: Constraints) -> RefineSettings:
    """Refinement settings whose hard limits and penalties include the shortest link and the
    transmission angle asked for (c in the normalised frame)."""
    changes = {}
    if c.min_link is not None:
        changes["min_link"] = max(settings.min_link, LINK_FACTOR * c.min_link)
    if c.min_transmission is not None:
        hard, soft = (np.sin(np.radians(min(c.min_transmission + e, 89.5))) ** 2
                      for e in EXTRA_DEGREES)  # fmt: skip
        changes["min_margin"] = max(settings.min_margin, float(hard))
        changes["soft_margin"] = max(settings.soft_margin, float(soft))
    return replace(settings, **changes)


class Barriers:
    """Ground-box and envelope terms of the refinement objective for one batch."""

    def __init__(self, batch: LinkageBatch, c: Constraints):
        self.c = c
        movable = torch.as_tensor(batch.valid).clone()
        if c.motor_at is not None:
            movable[:, 0] = False  # the pinned pivot was checked against both boxes up front
        self.ground = movable & torch.as_tensor(batch.fixed)
        self.every = movable

    def __call__(self, positions: torch.Tensor, x: torch.Tensor, y: torch.Tensor, rows) -> tuple:
        """(penalty (k,), ok (k,)) for candidates `rows` at positions (k, N, 2) whose joints
        move along x, y (k, N, T)."""
        penalty = positions.new_zeros(len(positions))
        ok = torch.ones(len(positions), dtype=torch.bool)
        for box, mask, xs, ys in (
            (self.c.ground_box, self.ground, positions[..., 0], positions[..., 1]),
            (self.c.envelope, self.every, x, y),
        ):
            if box is None:
                continue
            inside = torch.minimum(torch.minimum(xs - box.x0, box.x1 - xs),
                                   torch.minimum(ys - box.y0, box.y1 - ys))  # fmt: skip
            if inside.dim() == 3:
                inside = inside.amin(2)  # the worst crank angle of each joint
            m = mask[rows]
            penalty = penalty + torch.where(m, torch.relu(SOFT - inside), 0).pow(2).sum(1)
            with torch.no_grad():
                ok &= ~(m & (inside < HARD)).any(1)
        return penalty, ok


def screen(batch: LinkageBatch, frame: Similarity, c: Constraints) -> tuple[np.ndarray, dict]:
    """Which candidates (in the normalised frame) meet every constraint `c` (in the user's frame)
    at sampled crank angles once mapped by `frame`, and each constraint's (values, margins)."""
    positions = frame.apply(batch.positions)
    if c.motor_at is not None:  # pinned, up to the frame change's rounding: exactly there
        extent = np.ptp(positions, axis=1).max(1)
        near = np.linalg.norm(positions[:, 0] - c.motor_at, axis=1) <= ROUNDING * extent
        positions[near, 0] = c.motor_at
    user = LinkageBatch(positions, batch.fixed, batch.valid, batch.adjacency, batch.end_effector)
    measured = measure_batch(user, c)
    feasible = np.ones(len(batch), bool)
    for _, margin in measured.values():
        feasible &= margin >= 0
    return feasible, measured
