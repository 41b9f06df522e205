"""Is a linkage a working one-degree-of-freedom mechanism? Topology, geometry and motion checks.

A linkage is valid when its motor is a fixed pivot with a free crank tip, it assembles dyad by
dyad from the fixed joints and the crank tip, no two joints coincide and no link has zero length
in the assembly pose, and every dyad closes at every sampled crank angle (law of cosines,
|cos| <= 1). The margin is the smallest squared sine of any dyad's transmission angle over the
cycle: 0 means a toggle (locking) pose, so callers can demand a safety margin above it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from linkd.batch import LinkageBatch
from linkd.kinematics import Motion, crank_path, dyad, ops_for, trace
from linkd.mechanism import Mechanism
from linkd.topology import Plan, Status, assembly_plan

N_ANGLES = 200
COINCIDENT = 1e-6  # joints closer than this fraction of the mechanism's size coincide


@dataclass
class Validation:
    status: np.ndarray  # (B,) Status codes
    margin: np.ndarray  # (B,) min sin^2 of transmission angles; nan where topology fails
    plan: Plan
    motion: Motion | None  # joint paths, kept when asked for

    @property
    def valid(self) -> np.ndarray:
        return self.status == Status.VALID

    def end_effector_paths(self, batch: LinkageBatch) -> Any:
        """(B, T, 2) path of each end effector (requires the motion to be kept)."""
        rows = np.arange(len(batch))
        ee = batch.end_effector
        return np.stack([self.motion.x[rows, ee], self.motion.y[rows, ee]], -1)


def _centred(positions: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions less their valid joints' centroid (so that single precision keeps a mechanism
    far from the origin apart), and (B,) the RMS distance of valid joints from it."""
    count = np.maximum(valid.sum(1, keepdims=True), 1)
    centroid = (positions * valid[..., None]).sum(1) / count
    centred = positions - centroid[:, None]
    spread = ((centred**2).sum(-1) * valid).sum(1) / count[:, 0]
    return centred, np.sqrt(spread)


def geometry_status(batch: LinkageBatch) -> np.ndarray:
    """(B,) ZERO_LENGTH_LINK / COINCIDENT_JOINTS / VALID from the assembly pose alone."""
    centred, scale = _centred(batch.positions, batch.valid)
    pos = np.where(batch.valid[..., None], centred, np.nan).astype(np.float32)
    x, y = pos[..., 0], pos[..., 1]  # padding is nan, so it is close to nothing
    dx = x[:, :, None] - x[:, None, :]
    dy = y[:, :, None] - y[:, None, :]
    d2 = dx * dx
    d2 += dy * dy
    tol = COINCIDENT * np.maximum(scale, 1e-12)
    close = d2 <= (tol**2).astype(np.float32)[:, None, None]
    status = np.zeros(len(batch), dtype=np.int64)
    rows = np.flatnonzero(close.sum((1, 2)) > batch.valid.sum(1))  # more than the diagonal
    if len(rows):
        valid = batch.valid[rows]
        pair = valid[:, :, None] & valid[:, None, :] & ~np.eye(pos.shape[1], dtype=bool)
        near, adj = close[rows] & pair, batch.adjacency[rows]
        status[rows[(near & ~adj).any((1, 2))]] = Status.COINCIDENT_JOINTS
        status[rows[(near & adj).any((1, 2))]] = Status.ZERO_LENGTH_LINK
    return status


def validate(
    batch: LinkageBatch,
    n_angles: int = N_ANGLES,
    keep_motion: bool = False,
    backend: str = "torch",
    chunk: int = 512,
    compiled: bool = False,
) -> Validation:
    """Validate every linkage of a batch at `n_angles` crank angles.

    backend: "torch" (multi-threaded, float32) or "numpy" (float64). The kinematics runs in
    chunks of `chunk` linkages so its working set stays in cache. compiled: fuse each dyad step
    with torch.compile (torch backend; compiles once per process, worth it for large batches;
    fastest with one torch thread per process, `torch.set_num_threads(1)`).
    """
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    status = plan.status.copy()
    pieces = _chunks(len(batch), chunk)
    geometry = np.concatenate([geometry_status(batch.subset(sl)) for sl in pieces] or [status])
    status[status == 0] = geometry[status == 0]
    margins, motions = [np.zeros(0)], []
    for sl in pieces:
        m = _trace_chunk(batch, plan, sl, n_angles, backend, compiled)
        margins.append(m.margin)
        if keep_motion:  # else let the chunk's paths go, so the next chunk reuses the memory
            motions.append(m)
    margin = np.concatenate(margins)
    status[(status == 0) & ~(margin > 0)] = Status.LOCKS
    margin = np.where(plan.status == 0, margin, np.nan)
    motion = None
    if keep_motion:
        motion = Motion(
            np.concatenate([m.x for m in motions]),
            np.concatenate([m.y for m in motions]),
            np.concatenate([m.step_margin for m in motions]),
        )
    return Validation(status, margin, plan, motion)


def _chunks(total: int, size: int) -> list[slice]:
    return [slice(start, start + size) for start in range(0, total, size)]


def _trace_chunk(
    batch: LinkageBatch, plan: Plan, sl: slice, n_angles: int, backend: str, compiled: bool
) -> Motion:
    """Kinematics of one chunk, returned as numpy arrays."""
    part = Plan(plan.status[sl], plan.dyad_node[sl], plan.dyad_parents[sl])
    if backend == "numpy":
        return trace(batch.positions[sl], part, n_angles)
    import torch

    with torch.no_grad():
        positions = torch.as_tensor(batch.positions[sl], dtype=torch.float32)
        m = trace(positions, part, n_angles, compiled=compiled)
    return Motion(m.x.numpy(), m.y.numpy(), m.step_margin.double().numpy())


def transmission_degrees(margin: Any) -> Any:
    """The worst transmission angle (folded into 0..90 degrees) of a margin, its squared sine."""
    return np.degrees(np.arcsin(np.sqrt(np.clip(margin, 0.0, 1.0))))


def validate_mechanism(mech: Mechanism, n_angles: int = N_ANGLES) -> tuple[Status, float]:
    """Verdict and margin for one mechanism, in float64."""
    result = validate(LinkageBatch.from_mechanisms([mech]), n_angles, backend="numpy")
    return Status(int(result.status[0])), float(result.margin[0])


def check_new_node(
    prefix_paths: Any,
    prefix_fixed: Any,
    node_fixed: Any,
    node_position: Any,
    node_links: Any,
) -> tuple[Any, Any, Any]:
    """Does adding joint t keep each prefix of t joints a valid mechanism? Batched over B.

    prefix_paths: (B, t, T, 2) paths of the joints already accepted (angle index 0 is the
    assembly pose); prefix_fixed: (B, t) bool; node_fixed: (B,) bool; node_position: (B, 2);
    node_links: (B, t) bool, links from the new joint to earlier joints. Numpy or torch.
    Returns (ok (B,) bool, the new joint's path (B, T, 2), its margin (B,), 1 for ground).
    """
    ops = ops_for(prefix_paths)
    bsz, t, n_angles, _ = prefix_paths.shape
    still = ops.materialise(node_position[:, None, :], (bsz, n_angles, 2))
    ones = ops.materialise(ops.asarray(1.0, prefix_paths), (bsz,))
    if t == 0:
        return node_fixed, still, ones
    assembly = prefix_paths[:, :, 0]
    if t == 1:
        x, y = crank_path(assembly[:, 0], node_position, ops.angles(n_angles, assembly), ops)
        ok = ~node_fixed & node_links[:, 0] & prefix_fixed[:, 0]
        return ok, ops.stack([x, y], -1), ones
    # Parents: the two lowest-index joints the new one links to (a dyad has exactly two).
    order = ops.argsort(ops.where(node_links, 0, 1), 1)
    b = ops.index(np.arange(bsz), prefix_paths)
    p1, p2 = prefix_paths[b, order[:, 0]], prefix_paths[b, order[:, 1]]
    e1, e2 = p2[:, 0] - p1[:, 0], node_position - p1[:, 0]
    r1sq = (e2**2).sum(-1)[:, None]
    r2sq = ((node_position - p2[:, 0]) ** 2).sum(-1)[:, None]
    side = ops.where(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] >= 0, 1.0, -1.0)[:, None]
    x, y, sin2 = dyad(p1[..., 0], p1[..., 1], p2[..., 0], p2[..., 1], r1sq, r2sq, side, ops)
    margin = ops.amin(sin2, (1,))
    spread = ((assembly - assembly.mean(1)[:, None]) ** 2).sum(-1).mean(1) ** 0.5
    gap = ops.amin(((assembly - node_position[:, None]) ** 2).sum(-1), (1,)) ** 0.5
    apart = gap > COINCIDENT * ops.clamp_min(spread, 1e-12)
    ok_free = ~node_fixed & (node_links.sum(1) == 2) & (margin > 0)
    ok_ground = node_fixed & ((node_links & ~prefix_fixed).sum(1) == 0)
    ok = (ok_free | ok_ground) & apart
    path = ops.where(node_fixed[:, None, None], still, ops.stack([x, y], -1))
    return ok, path, ops.where(node_fixed, ones, margin)
