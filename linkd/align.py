"""Align a batch of candidate curves to a target: for each candidate, the similarity (rotation,
optional reflection, uniform scale, translation) that brings it closest to the target in Chamfer
distance.

The design pipeline ranks hundreds of candidate mechanisms per target by this aligned distance,
so every step is batched over candidates. Curves are closed polylines, points in path order.

1. Both curves are normalised (centroid and RMS radius of the curve as a wire): a first guess
   of translation and scale.
2. Rotation and reflection guesses: the peaks of the cross-correlation (an FFT over angle) of
   polar occupancy histograms, angle x radius, of candidate and target.
3. Every guess is improved by a few steps of iterative closest points on a few dozen points per
   curve; the best one is then polished on more points. Each step pairs every point with its
   closest point on the other curve's polyline, in both directions, and solves for the
   similarity in closed form (point-to-line least squares, reweighted towards the Chamfer
   distance's sum of distances). A step keeps each guess's reflection.
4. The Chamfer distance of the moved candidate to the target is measured on all points.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch

from linkd.curves import curve_moments
from linkd.geometry import Similarity

ANGLE_BINS = 64  # rotation resolution of the histogram correlation (5.6 degrees)
RING_CENTRES = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5)  # radial bins of the histograms, in RMS radii
GUESSES = 8  # rotation/reflection guesses scored per candidate
KEEP = 3  # of which the best are improved by ICP
SEARCH_POINTS, SEARCH_STEPS = 32, 2  # points per curve and ICP steps for every guess
POLISH_POINTS, POLISH_STEPS = 64, 6  # the same for the best guess
STIFFNESS = 0.01  # weight of the full point-to-point gap beside the point-to-line gap
HUBER = 0.3  # gaps below HUBER x the mean gap count quadratically, larger ones linearly
FLIP = torch.tensor([[1.0, 0.0], [0.0, -1.0]])  # the reflection y -> -y


@dataclass(frozen=True)
class SimilarityBatch:
    """B similarities p -> scale[b] * rotation[b] @ p + translation[b], as numpy arrays."""

    scale: np.ndarray  # (B,)
    rotation: np.ndarray  # (B, 2, 2), det -1 where the transform reflects
    translation: np.ndarray  # (B, 2)

    def __len__(self) -> int:
        return len(self.scale)

    def __getitem__(self, b: int) -> Similarity:
        return Similarity(float(self.scale[b]), self.rotation[b].copy(), self.translation[b].copy())

    def __iter__(self) -> Iterator[Similarity]:
        return (self[b] for b in range(len(self)))

    @property
    def reflects(self) -> np.ndarray:
        """(B,) bool: which transforms mirror the plane (and so reverse a path's direction)."""
        return np.linalg.det(self.rotation) < 0

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform per-candidate points (B, n, 2)."""
        moved = np.einsum("bij,bnj->bni", self.rotation, np.asarray(points, dtype=np.float64))
        return self.scale[:, None, None] * moved + self.translation[:, None, :]


def align(
    candidates: np.ndarray | torch.Tensor,
    target: np.ndarray | torch.Tensor,
    reflect: bool = True,
) -> tuple[SimilarityBatch, np.ndarray]:
    """Best similarities mapping candidate curves (B, n, 2) onto a closed target curve (m, 2).

    Returns the similarities and the Chamfer distances (B,) of the moved candidates to the
    target, in the target's units (inf for a candidate with non-finite points). With
    `reflect=False` only proper rotations are tried. The target is used as given: pass
    `curves.resample(target)` for a distance that does not depend on how densely each part of
    the target was sampled.
    """
    with torch.no_grad():
        cand = torch.as_tensor(candidates).detach().to("cpu", torch.float64)
        goal = torch.as_tensor(target).detach().to("cpu", torch.float64)
        if len(cand) == 0:
            return SimilarityBatch(np.ones(0), np.zeros((0, 2, 2)), np.zeros((0, 2))), np.zeros(0)
        goal_centre, goal_radius = curve_moments(goal)
        cand_centre, cand_radius = curve_moments(cand)
        cand_radius = cand_radius.clamp_min(1e-12 * float(goal_radius))  # a point-like candidate
        q = (goal - goal_centre) / goal_radius
        p = (cand - cand_centre[:, None]) / cand_radius[:, None, None]

        B, p32, q32 = len(p), p.float(), q.float()
        flips = torch.stack([torch.eye(2), FLIP][: 1 + reflect])
        p_few, q_few = _subsample(p32, SEARCH_POINTS), _subsample(q32, SEARCH_POINTS)
        p_more, q_more = _subsample(p32, POLISH_POINTS), _subsample(q32, POLISH_POINTS)
        guesses = _rotation_guesses(p_more, q_more, flips)
        pose = (torch.ones(len(guesses)), guesses, torch.zeros(len(guesses), 2))
        pose = _icp(p_few.repeat_interleave(GUESSES, 0), q_few, pose, 0)  # score the guesses
        pose = _icp(p_few.repeat_interleave(KEEP, 0), q_few, _best(pose, B, KEEP), SEARCH_STEPS)
        pose = _icp(p_more, q_more, _best(pose, B, 1), POLISH_STEPS)
        scale, rotation, shift = (x.double() for x in pose[:3])

        distance = _chamfer_exact(_move(p, scale, rotation, shift), q) * goal_radius
        scale = goal_radius * scale / cand_radius
        translation = goal_radius * shift + goal_centre
        translation -= scale[:, None] * torch.einsum("bij,bj->bi", rotation, cand_centre)
        sims = SimilarityBatch(scale.numpy(), rotation.numpy(), translation.numpy())
        return sims, distance.nan_to_num(nan=np.inf).numpy()


def _best(pose: tuple, candidates: int, keep: int) -> tuple:
    """Of poses grouped by candidate, the `keep` of lowest distance for each candidate."""
    distance = pose[3].reshape(candidates, -1)
    pick = distance.topk(keep, dim=1, largest=False).indices
    pick = (pick + distance.shape[1] * torch.arange(candidates)[:, None]).reshape(-1)
    return tuple(x[pick] for x in pose[:3])


def _subsample(points: torch.Tensor, k: int) -> torch.Tensor:
    """About k points, every (n / k)-th: the curve's own sampling density is kept, as the
    Chamfer distance of all points weighs each part of a curve by its number of points."""
    n = points.shape[-2]
    return points[..., torch.linspace(0, n, k + 1)[:-1].long(), :] if n > k else points


def _rotations(angle: torch.Tensor) -> torch.Tensor:
    c, s = torch.cos(angle), torch.sin(angle)
    return torch.stack([torch.stack([c, -s], -1), torch.stack([s, c], -1)], -2)


def _histogram(points: torch.Tensor) -> torch.Tensor:
    """Polar occupancy (N, rings, angle bins) of normalised curves (N, k, 2), soft in both."""
    rings = torch.tensor(RING_CENTRES)
    ring_weight = torch.exp(-(((points.norm(dim=-1)[..., None] - rings) / 0.5) ** 2))
    where = torch.atan2(points[..., 1], points[..., 0]) * (ANGLE_BINS / (2 * np.pi))
    low = where.floor()
    upper = (where - low)[..., None]
    low = low.long()[..., None] % ANGLE_BINS
    bins = torch.zeros(*points.shape[:2], ANGLE_BINS)
    bins.scatter_add_(2, low, 1 - upper).scatter_add_(2, (low + 1) % ANGLE_BINS, upper)
    return torch.einsum("nkr,nka->nra", ring_weight, bins)


def _rotation_guesses(p: torch.Tensor, q: torch.Tensor, flips: torch.Tensor) -> torch.Tensor:
    """(B * GUESSES, 2, 2) orthogonal matrices at the highest histogram correlation peaks."""
    B, F = len(p), len(flips)
    flipped = torch.einsum("fij,bkj->bfki", flips, p).reshape(B * F, -1, 2)
    spectrum = torch.fft.rfft(_histogram(flipped), dim=-1)
    target = torch.fft.rfft(_histogram(q[None]), dim=-1)
    score = torch.fft.irfft(spectrum.conj() * target, n=ANGLE_BINS, dim=-1).sum(1)  # (B*F, bins)
    peak = (score >= score.roll(1, -1)) & (score >= score.roll(-1, -1))
    score = score.where(peak, -torch.inf).reshape(B, F * ANGLE_BINS)
    best = score.topk(GUESSES, dim=1).indices.reshape(-1)  # rotation by best bins
    angle = (best % ANGLE_BINS) * (2 * np.pi / ANGLE_BINS)
    return _rotations(angle.float()) @ flips[best // ANGLE_BINS]


def _icp(p: torch.Tensor, q: torch.Tensor, pose: tuple, steps: int) -> tuple:
    """Iterative closest points for curves p (B, k, 2) onto q (m, 2) from pose (scale (B,),
    rotation (B, 2, 2), shift (B, 2)); the rotations' reflections are kept. Returns the pose
    with the lowest distance seen, and that distance: the Chamfer distance between each
    curve's points and the other curve's polyline."""
    scale, rotation, shift = pose
    B, k, m = *p.shape[:2], len(q)
    sign = torch.linalg.det(rotation).sign()
    flip = torch.stack([torch.ones_like(sign), sign], -1)[:, None]  # (B, 1, 2)
    u = p * flip  # the reflection comes first, then a proper rotation
    goal_q = q.expand(B, m, 2)
    weight = torch.cat([torch.full((B, k), 0.5 / k), torch.full((B, m), 0.5 / m)], dim=1)
    best = (*pose, torch.full((B,), torch.inf))
    for step in range(steps + 1):
        x = _move(p, scale, rotation, shift)
        nearest_q, nearest_x = _nearest(x, q)
        on_q = _closest_on_polyline(x, q, nearest_q)
        on_p = _closest_on_polyline(goal_q, x, nearest_x)
        gap = torch.cat([(x - on_q.point).norm(dim=-1), (q - on_p.point).norm(dim=-1)], dim=1)
        distance = (weight * gap).sum(1)
        better = distance < best[3]
        best = tuple(
            torch.where(better.reshape(-1, *[1] * (new.dim() - 1)), new, old)
            for new, old in zip((scale, rotation, shift, distance), best)
        )
        if step == steps:
            return best
        u_start, u_end = _gather(u, on_p.start), _gather(u, (on_p.start + 1) % k)
        source = torch.cat([u, u_start + on_p.fraction[..., None] * (u_end - u_start)], dim=1)
        goal = torch.cat([on_q.point, goal_q], dim=1)
        normal = torch.cat([on_q.normal, on_p.normal], dim=1)
        robust = weight / torch.maximum(gap, HUBER * distance[:, None])
        scale, angle, shift = _fit_similarity(source, goal, normal, robust)
        rotation = _rotations(angle) * flip


class _Closest(NamedTuple):
    start: torch.Tensor  # (B, N) index of the polyline edge's first vertex
    fraction: torch.Tensor  # (B, N) where on that edge, 0..1
    point: torch.Tensor  # (B, N, 2) the closest point
    normal: torch.Tensor  # (B, N, 2) the edge's unit normal


def _closest_on_polyline(points: torch.Tensor, poly: torch.Tensor, vertex: torch.Tensor):
    """Closest points to points (B, N, 2) on closed polylines (B, M, 2) or one (M, 2), given
    each point's nearest vertex (B, N): on the edge before or after that vertex, whichever the
    point lies beside (seen along the tangent there)."""
    M = poly.shape[-2]
    edges = poly.roll(-1, -2) - poly  # edge v runs from vertex v to v + 1
    tangents = edges + edges.roll(1, -2)
    beside = ((points - _gather(poly, vertex)) * _gather(tangents, vertex)).sum(-1)
    start = torch.where(beside < 0, (vertex - 1) % M, vertex)
    a, edge = _gather(poly, start), _gather(edges, start)
    length2 = (edge * edge).sum(-1).clamp_min(1e-30)
    fraction = (((points - a) * edge).sum(-1) / length2).clamp(0, 1)
    normal = torch.stack([-edge[..., 1], edge[..., 0]], -1) / length2.sqrt()[..., None]
    return _Closest(start, fraction, a + fraction[..., None] * edge, normal)


def _gather(points: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """Points (B, M, 2), or (M, 2) shared by all, at integer index (B, N) -> (B, N, 2)."""
    if points.dim() == 2:
        return points[index]
    return points.gather(1, index[..., None].expand(-1, -1, 2))


def _fit_similarity(source, goal, normal, weight):
    """Weighted least-squares scale s, angle a, shift t with s * rot(a) @ source + t ~ goal.

    A pair's gap counts along the goal's normal (point to line: a curve may slide along itself,
    which lets ICP converge in a few steps), plus STIFFNESS times the whole gap. The problem is
    linear in v = (s cos a, s sin a, t): one 4 x 4 solve per candidate.
    """
    sx, sy = source.unbind(-1)
    nx, ny = normal.unbind(-1)
    gx, gy = goal.unbind(-1)
    # point to line: the gap along n is row . v - n . goal
    rows = torch.stack([nx * sx + ny * sy, ny * sx - nx * sy, nx, ny], -1)  # (B, N, 4)
    weighted = rows * weight[..., None]
    lhs = weighted.transpose(1, 2) @ rows
    rhs = (weighted * (nx * gx + ny * gy)[..., None]).sum(1)
    # point to point, summed in closed form
    w = weight[..., None]
    total, (mx, my), sq = weight.sum(1), (w * source).sum(1).unbind(-1), (w * source**2).sum((1, 2))
    zero = torch.zeros_like(total)
    lhs += STIFFNESS * torch.stack(
        [
            torch.stack([sq, zero, mx, my], -1),
            torch.stack([zero, sq, -my, mx], -1),
            torch.stack([mx, -my, total, zero], -1),
            torch.stack([my, mx, zero, total], -1),
        ],
        -2,
    )
    rhs += STIFFNESS * torch.stack(
        [
            (weight * (sx * gx + sy * gy)).sum(1),
            (weight * (sx * gy - sy * gx)).sum(1),
            (weight * gx).sum(1),
            (weight * gy).sum(1),
        ],
        -1,
    )
    c, s, tx, ty = torch.linalg.solve_ex(lhs, rhs)[0].unbind(-1)
    return torch.hypot(c, s), torch.atan2(s, c), torch.stack([tx, ty], -1)


def _move(p: torch.Tensor, scale: torch.Tensor, rotation: torch.Tensor, shift: torch.Tensor):
    return scale[:, None, None] * p @ rotation.transpose(1, 2) + shift[:, None]


def _squared_distances(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """|a_i - b_j|^2 for a (B, n, 2) and b (m, 2), as (B, n, m), through one matrix product."""
    flat = torch.addmm((b * b).sum(-1), a.reshape(-1, 2), b.T, alpha=-2)
    return flat.view(*a.shape[:2], len(b)).add_((a * a).sum(-1)[..., None]).clamp_min_(0)


def _nearest(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Index of the nearest point of b (m, 2) to each point of a (B, n, 2), and of a to each of b.

    Both come from one pass: the low bits of each single-precision squared distance are
    replaced by its (row, column) code, so a plain minimum (much faster than a minimum with
    indices) also says where it is; near-ties (within 0.05 % in squared distance) go either way.
    """
    n, m = a.shape[1], len(b)
    row_bits, col_bits = (n - 1).bit_length(), (m - 1).bit_length()
    assert row_bits + col_bits <= 12, "for curves of up to 64 points"
    code = (torch.arange(n)[:, None] << col_bits | torch.arange(m)).int()
    keys = _squared_distances(a.float(), b.float()).view(torch.int32)
    keys = keys.bitwise_and_(-1 << (row_bits + col_bits)).bitwise_or_(code).view(torch.float32)
    col_mask, row_mask = (1 << col_bits) - 1, (1 << row_bits) - 1
    to_b = keys.amin(2).view(torch.int32).bitwise_and(col_mask)
    to_a = keys.amin(1).view(torch.int32).bitwise_right_shift(col_bits).bitwise_and(row_mask)
    return to_b.long().clamp_max(m - 1), to_a.long().clamp_max(n - 1)  # NaN rows: any index


def _chamfer_exact(a: torch.Tensor, b: torch.Tensor, chunk: int = 8) -> torch.Tensor:
    """Chamfer distances (B,) of a (B, n, 2) to b (m, 2) in double precision, a few candidates
    at a time so that each (chunk, n, m) block of distances stays in the processor's cache."""
    parts = []
    for part in a.split(chunk):
        dx, dy = part[..., 0, None] - b[:, 0], part[..., 1, None] - b[:, 1]
        d2 = dx.mul_(dx).addcmul_(dy, dy)
        parts.append(d2.amin(2).sqrt().mean(1) + d2.amin(1).sqrt().mean(1))
    return torch.cat(parts)
