"""Batched forward kinematics of dyadic linkages: B mechanisms x T crank angles at once.

The same code runs on numpy arrays and on torch tensors (differentiable, any dtype and device),
through a tiny table of the few operations where the two libraries differ. Each dyad keeps the
side of the line through its two parents that it has in the assembly pose, so a mechanism never
switches branch; where a dyad cannot close, its squared transmission sine turns negative.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from linkd.topology import Plan

EPS = 1e-12  # floor for squared distances and dyad heights: keeps values and gradients finite

_NUMPY = SimpleNamespace(
    sqrt=np.sqrt,
    cos=np.cos,
    sin=np.sin,
    where=np.where,
    clamp_min=np.maximum,
    stack=lambda xs, dim: np.stack(xs, axis=dim),
    amin=lambda x, dims: x.min(axis=dims),
    argsort=lambda x, dim: np.argsort(x, axis=dim, kind="stable"),
    materialise=lambda x, shape: np.broadcast_to(x, shape).copy(),
    index=lambda idx, like: np.asarray(idx),
    mask=lambda m, like: np.asarray(m, dtype=bool),
    angles=lambda n, like: np.arange(n, dtype=like.dtype) * (2 * np.pi / n),
    asarray=lambda values, like: np.asarray(values, dtype=like.dtype),
)


def _torch_ops() -> SimpleNamespace:
    import torch

    return SimpleNamespace(
        sqrt=torch.sqrt,
        cos=torch.cos,
        sin=torch.sin,
        where=torch.where,
        clamp_min=torch.clamp_min,
        stack=lambda xs, dim: torch.stack(xs, dim=dim),
        amin=lambda x, dims: x.amin(dim=dims),
        argsort=lambda x, dim: torch.argsort(x, dim=dim, stable=True),
        materialise=lambda x, shape: x.expand(shape).clone(),
        index=lambda idx, like: torch.as_tensor(idx, dtype=torch.long, device=like.device),
        mask=lambda m, like: torch.as_tensor(m, dtype=torch.bool, device=like.device),
        angles=lambda n, like: (
            torch.arange(n, dtype=like.dtype, device=like.device) * (2 * np.pi / n)
        ),
        asarray=lambda values, like: torch.as_tensor(values, dtype=like.dtype, device=like.device),
    )


def ops_for(array: Any) -> SimpleNamespace:
    """The operation table for a numpy array or a torch tensor."""
    return _NUMPY if isinstance(array, np.ndarray) else _torch_ops()


@dataclass
class Motion:
    """Joint paths and dyad transmission over one crank revolution."""

    x: Any  # (B, N, T) joint x at the crank angles (counter-clockwise from the assembly pose)
    y: Any  # (B, N, T) joint y
    step_margin: Any  # (B, S) min over angles of each plan step's sin^2 transmission; 1 if unused
    sin2: Any = None  # (B, S, T) the same at every angle, when asked for (`full=True`)

    @property
    def paths(self) -> Any:
        """(B, N, T, 2) joint positions."""
        return ops_for(self.x).stack([self.x, self.y], -1)

    @property
    def margin(self) -> Any:
        """(B,) distance to locking: min over dyads and angles of sin^2(transmission angle)."""
        return ops_for(self.step_margin).amin(self.step_margin, (1,))


def dyad(x1: Any, y1: Any, x2: Any, y2: Any, r1sq: Any, r2sq: Any, side: Any, ops: Any) -> tuple:
    """Place a joint at distances r1, r2 from moving parents (x1, y1), (x2, y2), on `side` (+-1).

    Returns the joint's coordinates and the squared sine of the angle between its two links
    (the transmission angle); that value is negative where the two circles do not meet.
    """
    return dyad_terms(x1, y1, x2, y2, r1sq, r2sq, side, ops)[:3]


def dyad_terms(x1: Any, y1: Any, x2: Any, y2: Any, r1sq: Any, r2sq: Any, side: Any, ops: Any):
    """`dyad`'s x, y, sin^2, then the terms its gradient is made of (`linkd.dyad_chain`).

    r1sq, r2sq and side are constant over the angles, so dividing by them is cheap: one
    full-size division per dyad.
    """
    dx, dy = x2 - x1, y2 - y1
    d2raw = dx * dx + dy * dy
    d2 = ops.clamp_min(d2raw, EPS)
    inv = 1 / d2
    a = 0.5 + (0.5 * (r1sq - r2sq)) * inv  # foot of the joint along p1->p2, as a fraction
    h2 = r1sq * inv - a * a  # squared height off the line p1->p2, as a fraction of |p1p2|^2
    root = ops.sqrt(ops.clamp_min(h2, EPS))
    h = side * root
    q = 1 / ops.clamp_min(r1sq * r2sq, EPS)
    terms = (dx, dy, d2raw, d2, inv, a, h2, root, h, q)
    return x1 + a * dx - h * dy, y1 + a * dy + h * dx, h2 * d2 * d2 * q, terms


def assembly_geometry(positions: Any, plan: Plan, ops: SimpleNamespace) -> tuple:
    """Squared link lengths and branch side of every plan step, from the assembly pose."""
    b = ops.index(np.arange(positions.shape[0])[:, None], positions)
    node = ops.index(plan.dyad_node, positions)
    i = ops.index(plan.dyad_parents[..., 0], positions)
    j = ops.index(plan.dyad_parents[..., 1], positions)
    pk, pi, pj = positions[b, node], positions[b, i], positions[b, j]
    r1sq = ((pk - pi) ** 2).sum(-1)
    r2sq = ((pk - pj) ** 2).sum(-1)
    cross = (pj[..., 0] - pi[..., 0]) * (pk[..., 1] - pi[..., 1]) - (pj[..., 1] - pi[..., 1]) * (
        pk[..., 0] - pi[..., 0]
    )
    side = ops.where(cross >= 0, 1.0, -1.0)
    return r1sq, r2sq, side


def crank_path(pivot: Any, tip: Any, angles: Any, ops: SimpleNamespace) -> tuple:
    """Coordinates (B, T) of a crank tip turned counter-clockwise about its pivot, by angles
    (T,) shared by all or (B, T) of each."""
    vx, vy = (tip[:, 0] - pivot[:, 0])[:, None], (tip[:, 1] - pivot[:, 1])[:, None]
    c, s = ops.cos(angles), ops.sin(angles)
    if len(angles.shape) == 1:
        c, s = c[None], s[None]
    return pivot[:, 0:1] + c * vx - s * vy, pivot[:, 1:2] + s * vx + c * vy


def _step(xs: Any, ys: Any, i: Any, j: Any, k: Any, r1sq: Any, r2sq: Any, side: Any, ops: Any):
    """Solve joint k (B,) of every linkage from its parents i, j in place; return its sin^2."""
    b = ops.index(np.arange(xs.shape[0]), xs)
    x, y, sin2 = dyad(xs[b, i], ys[b, i], xs[b, j], ys[b, j], r1sq, r2sq, side, ops)
    xs[b, k], ys[b, k] = x, y
    return sin2


_COMPILED: dict = {}


def _compiled_step() -> Any:
    """`_step` fused into one kernel by torch.compile, returning the min sin^2 (B,).

    Needs a C++ compiler; the first call compiles for tens of seconds, so it pays off only for
    large batches (benchmarks, data generation).
    """
    if "step" not in _COMPILED:
        import torch

        ops = _torch_ops()

        def step_margin(xs, ys, i, j, k, r1sq, r2sq, side):
            return _step(xs, ys, i, j, k, r1sq, r2sq, side, ops).amin(1)

        _COMPILED["step"] = torch.compile(step_margin, dynamic=True)
    return _COMPILED["step"]


def trace(
    positions: Any, plan: Plan, angles: int | Any = 200, full: bool = False, compiled: bool = False
) -> Motion:
    """Move every joint of a batch through a crank revolution.

    positions: (B, N, 2) assembly pose, node 0 the motor pivot and node 1 the crank tip.
    plan: the batch's solve order (`topology.assembly_plan`).
    angles: a count T (angles 2*pi*k/T) or explicit crank angles relative to the assembly pose,
        (T,) for all or (B, T), one row per mechanism.
    full: also keep every dyad's transmission at every angle (for smooth penalties).
    compiled: run each step as one torch.compile'd kernel (torch tensors; ignored with `full`
        or for positions that require gradients).
    """
    ops = ops_for(positions)
    bsz, n, _ = positions.shape
    if isinstance(angles, int):
        angles = ops.angles(angles, positions)
    else:
        angles = ops.asarray(angles, positions)
    t = angles.shape[-1]
    # Slot n is scratch: unused plan steps write there (a copy of the crank tip).
    extended = ops.stack([positions[:, k] for k in [*range(n), 1]], 1)
    xs = ops.materialise(extended[:, :, 0, None], (bsz, n + 1, t))
    ys = ops.materialise(extended[:, :, 1, None], (bsz, n + 1, t))
    xs[:, 1], ys[:, 1] = crank_path(positions[:, 0], positions[:, 1], angles, ops)
    xs[:, n], ys[:, n] = xs[:, 1], ys[:, 1]
    r1sq, r2sq, side = assembly_geometry(extended, plan, ops)
    # (S, 3, B) parents and node of every step, converted once.
    order = np.concatenate([plan.dyad_parents, plan.dyad_node[..., None]], 2).transpose(1, 2, 0)
    order = ops.index(np.ascontiguousarray(order), xs)
    steps = plan.dyad_node.shape[1]
    if not steps:
        return Motion(xs[:, :n], ys[:, :n], ops.materialise(ops.asarray(1.0, positions), (bsz, 1)))
    if getattr(positions, "requires_grad", False):
        from linkd.dyad_chain import DyadChain

        xs, ys, sin2 = DyadChain.apply(xs, ys, r1sq, r2sq, side, order)
        margin = sin2.amin(2)
    else:
        step = _compiled_step() if compiled and not full else None
        margins, rows = [], []
        for s in range(steps):
            args = (xs, ys, *order[s], r1sq[:, s, None], r2sq[:, s, None], side[:, s, None])
            if step is not None:
                margins.append(step(*args))
                continue
            rows.append(_step(*args, ops))
            margins.append(ops.amin(rows[-1], (1,)))
        margin, sin2 = ops.stack(margins, 1), ops.stack(rows, 1) if full else None
    unused = ops.mask(plan.dyad_node == n, positions)
    step_margin = ops.where(unused, 1.0, margin)
    full_sin2 = ops.where(unused[:, :, None], 1.0, sin2) if full else None
    return Motion(xs[:, :n], ys[:, :n], step_margin, full_sin2)
