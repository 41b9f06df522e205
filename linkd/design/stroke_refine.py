"""Refine candidates on an open or timed target: joint positions and crank range together.

The refinement of `linkd.design.refine` (batched L-BFGS, the same buildability penalties over
the whole revolution, best iterate within the hard limits kept) with another objective: the
end effector is traced over the candidate's crank range [a, a + span] as well as over the whole
revolution (the revolution for the penalties: the machine must stay valid on its return
stroke too), and the crank range is two more variables, riding along as an extra row of the
position array.

- open, untimed: Chamfer distance between the stroke and the target (open polylines), plus the
  distance of the stroke's ends from the target's ends; early on also the ordered distance of
  the stroke resampled by arc length (it pulls the stroke along the whole target).
- timed: the mean distance between each target sample and the end effector at its time (the
  timing error), plus a little Chamfer distance; a closed timed target keeps the span of one
  revolution and moves only its phase.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch

from linkd.batch import LinkageBatch
from linkd.constraints import Constraints
from linkd.kinematics import trace

from .refine import Objective, RefineResult, RefineSettings, Terms, point_to_polyline, refine
from .stroke import Goal, crank_ranges

STROKE_ANGLES = 128  # crank angles along an untimed stroke
END_WEIGHT = 0.5  # weight of the ends' distance beside the Chamfer distance
CHAMFER_WEIGHT = 0.2  # weight of the Chamfer distance beside the timing error
MIN_SPAN = 0.2  # radians: a stroke needs some of the revolution
REACH = 15.0  # joints beyond this distance of the target's centroid are penalised (strokes
# are short next to the machines that trace them)


def refine_stroke(
    batch: LinkageBatch,
    ranges: np.ndarray,
    goal: Goal,
    settings: RefineSettings | None = None,
    deadline: float | None = None,
    constraints: Constraints | None = None,
) -> tuple[RefineResult, np.ndarray]:
    """Refine positions and crank ranges (K, 2) of `batch` on `goal`; returns the result (its
    `chamfer` is the score: Chamfer distance, or timing error when timed) and the ranges.
    `constraints`: as `refine` takes them (a motor point keeps the crank pivot where it is)."""
    # Paths here run over the stroke's crank range, not a whole turn: no acceleration limit.
    s = replace(settings or RefineSettings(), max_radius=REACH, soft_acceleration=0.0)
    extra = np.stack([ranges[:, 0], ranges[:, 1] - ranges[:, 0]], 1)[:, None]
    riding = LinkageBatch(np.concatenate([batch.positions, extra], 1), batch.fixed, batch.valid,
                          batch.adjacency, batch.end_effector)  # fmt: skip
    result = refine(riding, goal, s, deadline, StrokeObjective, constraints)
    ranges = crank_ranges(result.positions[:, -1, 0], result.positions[:, -1, 1])
    return RefineResult(result.positions[:, :-1], result.chamfer, result.iterations), ranges


class StrokeObjective(Objective):
    """The objective for a Goal; positions (k, N + 1, 2) carry the crank start and span in
    their last row."""

    def __init__(self, batch: LinkageBatch, plan, goal: Goal, s: RefineSettings,
                 constraints=None):  # fmt: skip
        super().__init__(batch, plan, goal.points, s, constraints)
        self.goal = goal
        count = len(goal.points) if goal.timed else STROKE_ANGLES
        self.fractions = goal.fractions(count, torch.zeros((), dtype=torch.float32))
        self.revolution = torch.arange(s.angles, dtype=torch.float32) * (2 * np.pi / s.angles)
        self.ends = self.target[[0, -1]]

    def __call__(self, riding: torch.Tensor, rows: torch.Tensor, ordered: torch.Tensor) -> Terms:
        s, goal = self.s, self.goal
        positions, a, span = riding[:, :-1], riding[:, -1, 0], riding[:, -1, 1]
        if goal.periodic:
            span = torch.full_like(span, 2 * np.pi)
        k = len(rows)
        along = a[:, None] + span[:, None] * self.fractions
        angles = torch.cat([self.revolution.expand(k, -1), along], 1)
        motion = trace(positions, self.plan_of(rows, positions.shape[1]), angles, full=True)
        path = motion.paths[torch.arange(k), self.end_effector[rows]]
        stroke = path[:, s.angles :]
        penalty, ok = self.penalties(positions, rows, motion)
        penalty = penalty + torch.relu(span - 2 * np.pi).pow(2) + torch.relu(MIN_SPAN - span).pow(2)
        chamfer = open_chamfer(stroke, self.target, closed=goal.closed)
        if goal.timed:
            score = (stroke - self.target).norm(dim=-1).mean(1)
            fit = score + CHAMFER_WEIGHT * chamfer
        else:
            score = chamfer
            ends = (stroke[:, [0, -1]] - self.ends).norm(dim=-1).mean(1)
            fit = chamfer + END_WEIGHT * ends
            if ordered.any():
                even = resample_open(stroke, len(self.target))
                fit = fit + ordered * (even - self.target).norm(dim=-1).mean(1)
        ok &= torch.isfinite(score) & (span <= 2 * np.pi + 1e-6) & (span >= MIN_SPAN / 2)
        return Terms(fit + s.penalty_weight * penalty, score, ok)


def open_chamfer(path: torch.Tensor, target: torch.Tensor, closed: bool = False) -> torch.Tensor:
    """(B,) Chamfer distance between polylines path (B, T, 2) and target (M, 2), open unless
    `closed`: each direction the mean distance from a curve's points to the other polyline, the
    path's points weighted by the arc length around them."""
    goal = target[None].expand(len(path), -1, -1)
    with torch.no_grad():
        d = torch.cdist(path, goal)
        near_target, near_path = d.argmin(2), d.argmin(1)
    to_path = point_to_polyline(goal, path, near_path, closed).mean(1)
    segment = (path[:, 1:] - path[:, :-1]).norm(dim=-1).detach()
    if closed:
        segment = torch.cat([segment, (path[:, :1] - path[:, -1:]).norm(dim=-1).detach()], 1)
        weight = 0.5 * (segment + segment.roll(1, 1))
    else:
        pad = torch.zeros_like(segment[:, :1])
        weight = 0.5 * (torch.cat([segment, pad], 1) + torch.cat([pad, segment], 1))
    weight = weight / weight.sum(1, keepdim=True).clamp_min(1e-12)
    to_target = (point_to_polyline(path, goal, near_target, closed) * weight).sum(1)
    return to_path + to_target


def resample_open(path: torch.Tensor, count: int) -> torch.Tensor:
    """(B, count, 2) points evenly spaced by arc length along open polylines (B, T, 2), from
    the first point to the last; differentiable in the positions."""
    seg = (path[:, 1:] - path[:, :-1]).norm(dim=-1)
    cum = torch.cat([torch.zeros_like(seg[:, :1]), seg.cumsum(1)], 1)  # (B, T)
    u = torch.linspace(0, 1, count, dtype=path.dtype) * cum[:, -1:]
    idx = torch.searchsorted(cum.detach().contiguous(), u.detach().contiguous(), right=True)
    idx = idx.clamp(1, path.shape[1] - 1)
    lo, hi = cum.gather(1, idx - 1), cum.gather(1, idx)
    frac = ((u - lo) / (hi - lo).clamp_min(1e-12)).clamp(0, 1)[..., None]
    a = path.gather(1, (idx - 1)[..., None].expand(-1, -1, 2))
    b = path.gather(1, idx[..., None].expand(-1, -1, 2))
    return a + frac * (b - a)
