"""Refine candidate mechanisms by batched L-BFGS through the differentiable kinematics.

The topology of every candidate stays fixed; all its joint positions (the assembly pose) move.
The objective is the Chamfer distance between each traced path and the target, measured
point-to-polyline and weighted by arc length so it matches a Chamfer distance between densely
resampled curves. Early on it also weighs an ordered term (the traced path, resampled by arc
length, against the target at its best cyclic shift and direction), which pulls a path towards
the parts of the target it misses instead of letting it settle on one lobe; every candidate is
refined in two variants, with a lighter and a heavier ordered term, and only the best variants
go on to the last, Chamfer-only iterations. The early iterations trace the path at fewer crank
angles (they only move it to the right region); their best iterates are traced finely again
before the last ones.
Soft penalties keep each candidate buildable: every dyad's squared transmission sine stays above
a margin over the whole cycle (far from locking, transmission angles away from 0 and pi), links
keep a minimum length, joints stay apart and near the curve, and no joint's acceleration at a
steady crank speed passes a limit (a machine that jerks, and loops too stiff for MuJoCo to keep
closed). The best iterate within the hard limits is kept per candidate, so refinement never
returns something worse than it was given or something invalid. A designer's constraints add
their own terms and hard limits (`linkd.design.constrained`); with a motor point the crank
pivot does not move.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np
import torch
from scipy.spatial import cKDTree

from linkd.batch import LinkageBatch
from linkd.constraints import Constraints
from linkd.design.lbfgs import minimise
from linkd.kinematics import trace
from linkd.topology import Plan, assembly_plan

KD_PAIRS = 2**18  # path points x target points from which nearest vertices come from k-d trees


@dataclass(frozen=True)
class RefineSettings:
    """Lengths are in the target's normalised frame (centroid 0, RMS radius 1)."""

    iterations: int = 210  # L-BFGS iterations in all (each a trial step of every variant)
    ordered_iterations: int = 80  # the first ones refine every variant and weigh the ordered
    keep: int = 16  # term too; the rest refine only the best `keep` variants, on Chamfer alone
    # Each candidate is refined in one variant per weight of the ordered term (next to the
    # Chamfer distance): a heavier one helps a path find parts of the target it misses, a
    # lighter one disturbs a good start less; the better variant is kept.
    ordered_weights: tuple[float, ...] = (0.1, 0.3)
    angles: int = 256  # crank angles the path is traced at
    ordered_angles: int = 128  # and in the first iterations, which only need its rough shape
    first_step: float = 0.01  # length of a steepest-descent step (start, or after a reset)
    min_margin: float = 0.02  # hard limit: sin^2 of every transmission angle, whole cycle
    soft_margin: float = 0.04  # the penalty pushes sin^2 up towards this
    min_link: float = 0.05  # hard limit on link length
    min_gap: float = 0.05  # hard limit on the distance between two joints, assembly pose
    penalty_weight: float = 10.0
    max_radius: float = 6.0  # joints beyond this distance of the target's centroid are penalised
    soft_acceleration: float = 60.0  # joint accelerations (per unit crank speed squared) past
    # this are penalised, 0: none. Designs grown in long searches reached hundreds, with loops
    # that MuJoCo could not keep closed (delivered designs mostly stay under 60)


@dataclass
class RefineResult:
    positions: np.ndarray  # (B, N, 2) best iterate within the hard limits (else the input)
    chamfer: np.ndarray  # (B,) its Chamfer distance to the target (inf if none was valid)
    iterations: int  # L-BFGS iterations run (all those asked for where every row converged
    # sooner: fewer means the deadline cut refinement short)

    @property
    def ok(self) -> np.ndarray:
        """(B,) whether any iterate met the hard limits."""
        return np.isfinite(self.chamfer)


def refine(
    batch: LinkageBatch,
    target: np.ndarray,
    settings: RefineSettings | None = None,
    deadline: float | None = None,
    objective: type[Objective] | None = None,
    constraints: Constraints | None = None,
    progress: Callable[[int, float], None] | None = None,
) -> RefineResult:
    """Refine every linkage of `batch` towards the closed `target` curve (M, 2).

    Positions and target must share a frame in which the target is normalised. `deadline` is a
    `time.monotonic()` value: refinement stops early when it passes. `objective`: another
    objective class (same constructor and call), for targets other than a closed path.
    `constraints` (in that frame) add the ground-box and envelope terms and pin the crank pivot
    to the motor point. `progress` is called after each iteration with the iterations done and
    the best Chamfer distance so far.
    """
    with single_thread():
        return _refine(batch, target, settings or RefineSettings(), deadline,
                       objective or Objective, constraints, progress)  # fmt: skip


@contextmanager
def single_thread() -> Iterator[None]:
    """Run torch on one thread. Batched kinematics and sampling are long chains of small
    operations, which threads only slow down: they wait on each other, and on a busy machine
    (measured with other jobs running) by a factor of tens."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def _phase(
    evaluate: Callable,
    x: torch.Tensor,
    rows: torch.Tensor,
    iterations: int,
    weights: torch.Tensor,
    s: RefineSettings,
    deadline: float | None,
    on_iteration: Callable[[int], None] | None = None,
) -> tuple[torch.Tensor, int]:
    """L-BFGS on the variants `rows` from x, with the ordered term's `weights` (per variant);
    returns the last iterates and the iterations run."""
    if iterations <= 0 or (deadline is not None and time.monotonic() > deadline):
        return x, 0
    return minimise(lambda v, r: evaluate(v, rows[r], weights[r]), x, iterations,
                    first_step=s.first_step, deadline=deadline,
                    on_iteration=on_iteration)  # fmt: skip


def _refine(
    batch: LinkageBatch,
    target: np.ndarray,
    s: RefineSettings,
    deadline: float | None,
    objective_type: type[Objective],
    constraints: Constraints | None = None,
    progress: Callable[[int, float], None] | None = None,
) -> RefineResult:
    copies = len(s.ordered_weights)
    variants = batch.subset(np.repeat(np.arange(len(batch)), copies))
    plan = assembly_plan(variants.adjacency, variants.fixed, variants.valid)
    fine = objective_type(variants, plan, target, s, constraints)
    coarse = fine
    if s.ordered_angles != s.angles:
        coarse = objective_type(variants, plan, target, replace(s, angles=s.ordered_angles),
                                constraints)  # fmt: skip
    objective = fine
    pinned = constraints is not None and constraints.motor_at is not None
    shape = variants.positions.shape
    best = variants.positions.copy()
    best_chamfer = np.full(len(variants), np.inf)

    def evaluate(x: torch.Tensor, rows: torch.Tensor, weight: torch.Tensor) -> tuple:
        x = x.detach().reshape(len(rows), *shape[1:]).requires_grad_(True)
        terms = objective(x, rows, weight)
        (grad,) = torch.autograd.grad(terms.loss.sum(), x)
        if pinned:
            grad[:, 0] = 0  # the crank pivot stays on the motor point
        chamfer = terms.chamfer.detach().numpy()
        index = rows.numpy()
        better = terms.ok.numpy() & (chamfer < best_chamfer[index])
        best[index[better]] = x.detach().numpy()[better]
        best_chamfer[index[better]] = chamfer[better]
        return terms.loss.detach(), grad.reshape(len(x), -1)

    x = torch.tensor(variants.positions, dtype=torch.float32).reshape(len(variants), -1)
    every = torch.arange(len(variants))
    weights = torch.tensor(s.ordered_weights, dtype=torch.float32).repeat(len(batch))
    zero = torch.zeros_like(weights)
    evaluate(x, every, zero)  # the start counts as an iterate too
    start, start_chamfer = best.copy(), best_chamfer.copy()
    objective, best_chamfer[:] = coarse, np.inf
    # First every variant, with the ordered term; then only the best few, on Chamfer alone.
    first = min(s.ordered_iterations, s.iterations)

    def report(before: int) -> Callable[[int], None] | None:
        """Progress after an iteration of the phase that starts after `before` iterations."""
        if progress is None:
            return None
        return lambda done: progress(before + done, float(best_chamfer.min()))

    x, done = _phase(evaluate, x, every, first, weights, s, deadline, report(0))
    # The first phase's best iterates, traced finely, replace the start where they are better.
    found = torch.tensor(best, dtype=torch.float32).reshape(len(variants), -1)
    objective, best[:], best_chamfer[:] = fine, start, start_chamfer
    evaluate(found, every, zero)
    keep = torch.as_tensor(np.argsort(best_chamfer, kind="stable")[: s.keep])
    _, more = _phase(evaluate, x[keep], keep, s.iterations - first, zero, s, deadline,
                     report(done))  # fmt: skip
    # Each candidate's better variant.
    pick = best_chamfer.reshape(len(batch), copies).argmin(1) + copies * np.arange(len(batch))
    positions = best[pick]
    if pinned:  # where it was given, not its single-precision rounding
        positions[:, 0] = batch.positions[:, 0]
    return RefineResult(positions, best_chamfer[pick], done + more)


@dataclass
class Terms:
    loss: torch.Tensor  # (B,) objective with penalties
    chamfer: torch.Tensor  # (B,) Chamfer distance of the traced path
    ok: torch.Tensor  # (B,) bool, within the hard limits


class Objective:
    """The refinement objective for one batch and one target, evaluated on joint positions."""

    def __init__(
        self,
        batch: LinkageBatch,
        plan: Plan,
        target: np.ndarray,
        s: RefineSettings,
        constraints: Constraints | None = None,
    ):
        self.plan, self.s = plan, s
        self.barriers = None
        if constraints:
            from linkd.design.constrained import Barriers

            self.barriers = Barriers(batch, constraints)
        self.end_effector = torch.as_tensor(batch.end_effector)
        self.target = torch.as_tensor(np.asarray(target, dtype=np.float32))
        upper = np.triu(batch.adjacency, 1)
        pairs = np.triu(batch.valid[:, :, None] & batch.valid[:, None, :], 1)
        self.links = torch.as_tensor(upper)
        self.unlinked = torch.as_tensor(pairs & ~upper)
        self.valid = torch.as_tensor(batch.valid)

    def __call__(self, positions: torch.Tensor, rows: torch.Tensor, ordered: torch.Tensor) -> Terms:
        """Terms for the candidates `rows` (k,) of the batch at their positions (k, N, 2), with
        the ordered term weighted by `ordered` (k,)."""
        s = self.s
        motion = trace(positions, self.plan_of(rows, positions.shape[1]), s.angles, full=True)
        path = motion.paths[torch.arange(len(rows)), self.end_effector[rows]]  # (k, T, 2)
        chamfer = polyline_chamfer(path, self.target)
        penalty, ok = self.penalties(positions, rows, motion)
        ok &= torch.isfinite(chamfer)
        loss = chamfer + s.penalty_weight * penalty
        if ordered.any():
            resampled = resample_closed(path, len(self.target))
            loss = loss + ordered * ordered_distance(resampled, self.target)
        return Terms(loss, chamfer, ok)

    def plan_of(self, rows: torch.Tensor, n: int) -> Plan:
        """The solve plan of the candidates `rows`, cut to the steps this subset needs."""
        index = rows.numpy()
        steps = int((self.plan.dyad_node[index] < n).sum(1).max(initial=0))
        return Plan(self.plan.status[index], self.plan.dyad_node[index, :steps],
                    self.plan.dyad_parents[index, :steps])  # fmt: skip

    def penalties(self, positions: torch.Tensor, rows: torch.Tensor, motion) -> tuple:
        """(k,) soft buildability (and constraint) penalty and (k,) whether the hard limits
        hold, for the candidates `rows` at positions (k, N, 2) moving as `motion`."""
        s = self.s
        sin2 = motion.sin2  # (k, S, T) transmissions
        links, unlinked, valid = self.links[rows], self.unlinked[rows], self.valid[rows]
        worst = sin2.amin(2)  # (B, S)
        lock = torch.relu(s.soft_margin - worst).pow(2).sum(1)
        d = torch.sqrt(((positions[:, :, None] - positions[:, None, :]) ** 2).sum(-1) + 1e-12)
        short = torch.where(links, torch.relu(1.5 * s.min_link - d), 0).pow(2).sum((1, 2))
        close = torch.where(unlinked, torch.relu(1.5 * s.min_gap - d), 0).pow(2).sum((1, 2))
        radius = torch.sqrt((positions**2).sum(-1) + 1e-12)
        far = torch.where(valid, torch.relu(radius - s.max_radius), 0).pow(2).sum(1)
        with torch.no_grad():
            ok = worst.amin(1) >= s.min_margin
            ok &= ~(links & (d < s.min_link)).any((1, 2))
            ok &= ~(unlinked & (d < s.min_gap)).any((1, 2))
        penalty = lock + short + close + far
        if s.soft_acceleration > 0:
            penalty = penalty + _acceleration_excess(motion, s.soft_acceleration)
        if self.barriers is not None:
            extra, inside = self.barriers(positions, motion.x, motion.y, rows)
            penalty, ok = penalty + extra, ok & inside
        return penalty, ok


def _acceleration_excess(motion, limit: float) -> torch.Tensor:
    """(k,) the squared share by which joints' accelerations at a steady crank speed pass
    `limit`, averaged over the turn and summed over the joints."""
    t = motion.x.shape[-1]
    scale = (t / (2 * torch.pi)) ** 2
    ax = (torch.roll(motion.x, 1, -1) - 2 * motion.x + torch.roll(motion.x, -1, -1)) * scale
    ay = (torch.roll(motion.y, 1, -1) - 2 * motion.y + torch.roll(motion.y, -1, -1)) * scale
    excess = torch.relu(torch.sqrt(ax**2 + ay**2 + 1e-12) / limit - 1)
    return excess.pow(2).mean(2).sum(1)


def polyline_chamfer(path: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """(B,) Chamfer distance between closed polylines path (B, T, 2) and target (M, 2).

    Each direction is the mean distance from a curve's points to the other polyline, the path's
    points weighted by the arc length around them (so uneven crank speed does not bias it).
    """
    with torch.no_grad():
        near_target, near_path = nearest_vertices(path.detach(), target)
    target = target[None].expand(len(path), -1, -1)
    to_path = point_to_polyline(target, path, near_path).mean(1)
    segment = (torch.roll(path, -1, 1) - path).norm(dim=-1).detach()
    weight = 0.5 * (segment + torch.roll(segment, 1, 1))
    weight = weight / weight.sum(1, keepdim=True).clamp_min(1e-12)
    to_target = (point_to_polyline(path, target, near_target) * weight).sum(1)
    return to_path + to_target


def nearest_vertices(path: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The nearest target vertex (B, T) of each path point and the nearest path vertex (B, M) of
    each target point, for paths (B, T, 2) and a target (M, 2). Small problems compare every
    pair at once (from |p|^2 - 2 p.q + |q|^2); past KD_PAIRS pairs a path, k-d trees are faster
    (the polish's 1024 path points against 1000 target points: the whole Chamfer distance, with
    its gradient, three times)."""
    b, t, _ = path.shape
    if t * len(target) < KD_PAIRS:
        target = target[None].expand(b, -1, -1)
        cross = torch.bmm(path, target.transpose(1, 2)).mul_(-2)  # (B, T, M)
        near_target = (cross + (target[0] ** 2).sum(1)).argmin(2)
        return near_target, cross.add_((path**2).sum(2)[:, :, None]).min(1).indices
    # A locked pose's NaN points get some vertex; their distances stay NaN.
    p, q = np.nan_to_num(path.double().numpy()), target.double().numpy()
    near_target = cKDTree(q).query(p.reshape(-1, 2))[1].reshape(b, t)
    # One tree for every path: each moved along x by its own multiple of a span wider than all
    # of them together, so a target point moved likewise finds its nearest in its own path.
    span = 4 * max(np.abs(p).max(), np.abs(q).max()) + 1
    shift = np.stack([np.arange(b) * span, np.zeros(b)], 1)[:, None]  # (B, 1, 2)
    near_path = cKDTree((p + shift).reshape(-1, 2)).query((q + shift).reshape(-1, 2))[1]
    near_path = near_path.reshape(b, -1) - t * np.arange(b)[:, None]
    return torch.as_tensor(near_target), torch.as_tensor(near_path)


def point_to_polyline(
    points: torch.Tensor, polyline: torch.Tensor, nearest: torch.Tensor, closed: bool = True
) -> torch.Tensor:
    """(B, P) distance from points (B, P, 2) to the polylines (B, Q, 2), closed or open: to the
    nearer of the two edges around each point's `nearest` vertex (B, P)."""
    q = polyline.shape[1]
    best = None
    for first in (nearest - 1, nearest):
        first = first % q if closed else first.clamp(0, q - 2)
        a = _gather(polyline, first)
        edge = _gather(polyline, (first + 1) % q) - a
        rel = points - a
        along = ((rel * edge).sum(-1) / (edge * edge).sum(-1).clamp_min(1e-18)).clamp(0, 1)
        gap = rel - along[..., None] * edge
        d2 = (gap * gap).sum(-1)
        best = d2 if best is None else torch.minimum(best, d2)
    return torch.sqrt(best + 1e-12)


def _gather(points: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """points (B, Q, 2) at index (B, P) -> (B, P, 2)."""
    return points.gather(1, index[..., None].expand(-1, -1, 2))


def resample_closed(path: torch.Tensor, count: int) -> torch.Tensor:
    """(B, count, 2) points evenly spaced by arc length along closed polylines (B, T, 2),
    starting at each path's first point; differentiable in the positions."""
    closed = torch.cat([path, path[:, :1]], 1)
    seg = (closed[:, 1:] - closed[:, :-1]).norm(dim=-1)
    cum = torch.cat([torch.zeros_like(seg[:, :1]), seg.cumsum(1)], 1)  # (B, T+1)
    u = torch.arange(count, dtype=path.dtype) / count * cum[:, -1:]
    idx = torch.searchsorted(cum.detach().contiguous(), u.detach().contiguous(), right=True)
    idx = idx.clamp(1, closed.shape[1] - 1)
    lo, hi = cum.gather(1, idx - 1), cum.gather(1, idx)
    frac = ((u - lo) / (hi - lo).clamp_min(1e-12))[..., None]
    a = closed.gather(1, (idx - 1)[..., None].expand(-1, -1, 2))
    b = closed.gather(1, idx[..., None].expand(-1, -1, 2))
    return a + frac * (b - a)


def ordered_distance(a: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """(B,) mean distance between points of a (B, M, 2) and the target (M, 2) in order, at the
    cyclic shift and direction of the target that fits best in the least-squares sense (found
    for all shifts at once by FFT correlation)."""
    m = len(target)
    with torch.no_grad():
        spectrum = torch.fft.rfft(a, dim=1)
        forward = torch.fft.rfft(target, dim=0)
        backward = torch.fft.rfft(target.flip(0), dim=0)
        # correlation[s] = sum_k a[k] . target[(k + s) % m]
        corr_f = torch.fft.irfft((spectrum.conj() * forward).sum(-1), n=m, dim=1)
        corr_b = torch.fft.irfft((spectrum.conj() * backward).sum(-1), n=m, dim=1)
        corr = torch.cat([corr_f, corr_b], 1)  # (B, 2m)
        choice = corr.argmax(1)
    k = torch.arange(m)
    shift = choice % m
    order = (k[None] + shift[:, None]) % m
    reverse = choice >= m
    index = torch.where(reverse[:, None], (m - 1 - order), order)
    d = torch.sqrt(((a - target[index]) ** 2).sum(-1) + 1e-12)
    return d.mean(1)
