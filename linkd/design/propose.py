"""Propose candidate mechanisms for a target curve and place each one on it.

LinkD samples designs for rotated and mirrored copies of the target as well as for the target
itself (test-time augmentation: the model has seen shapes in some orientations more than
others). Whatever copy a design was made for, it is then fitted onto the target by the
similarity (rotation, reflection, uniform scale, translation) that brings its path closest,
and ranked by the Chamfer distance that remains.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial, reduce

import numpy as np
import torch

from linkd.align import align
from linkd.batch import LinkageBatch, ancestors
from linkd.design.refine import resample_closed
from linkd.geometry import rotation
from linkd.sample import MOVES, spread
from linkd.validator import validate

from .parallel import PARTS, run_parts, split

# (conditioning curves (C, 200, 2), samples per curve, seed) -> graph matrices (C * S, 20, 24)
Proposer = Callable[[np.ndarray, int, int], np.ndarray]
HARMONICS = 16  # Fourier harmonics of the shape descriptor that pre-ranks sub-mechanisms
PINNED_POOL = 16  # with a motor point, paths are chosen from this many times as many by shape


@dataclass
class Candidates:
    """Valid candidate mechanisms placed on the target, best first."""

    batch: LinkageBatch  # positions in the target's normalised frame
    chamfer: np.ndarray  # (K,) Chamfer distance of each placed path to the target
    source: np.ndarray | None = None  # (K,) where each came from: an index into SOURCES
    refined: np.ndarray | None = None  # (K,) bool, whether refinement has had it (default none)
    ranges: np.ndarray | None = None  # (K, 2) crank ranges [a, b] on an open or timed target

    def __post_init__(self) -> None:
        if self.source is None:
            self.source = np.zeros(len(self.chamfer), int)
        if self.refined is None:
            self.refined = np.zeros(len(self.chamfer), bool)

    def __len__(self) -> int:
        return len(self.chamfer)

    def subset(self, rows: np.ndarray) -> Candidates:
        """The candidates `rows`, each with its error, source, refinement and crank range."""
        ranges = None if self.ranges is None else self.ranges[rows]
        return Candidates(self.batch.subset(rows), self.chamfer[rows], self.source[rows],
                          self.refined[rows], ranges)  # fmt: skip


def merged(first: Candidates, second: Candidates) -> Candidates:
    """The candidates of both, first's then second's (not re-sorted); crank ranges where both
    have them."""
    both = (first, second)
    ranges = None
    if first.ranges is not None and second.ranges is not None:
        ranges = np.concatenate([first.ranges, second.ranges])
    return Candidates(joined([first.batch, second.batch]),
                      *(np.concatenate([getattr(x, f) for x in both])
                        for f in ("chamfer", "source", "refined")), ranges)  # fmt: skip


SOURCES = ("model", "atlas", "round 2")  # the proposer, the atlas, the search around the best


def source_name(source: int, proposer: str) -> str:
    """The name of a candidate's source (an index into SOURCES) in reports: the proposer's own
    ("model" for LinkD, "random" for the generator), "atlas" or "round 2"."""
    return proposer if source == 0 else SOURCES[source]


def joined(batches: list[LinkageBatch]) -> LinkageBatch:
    """One batch of the linkages of several (all padded to the same number of joints)."""
    fields = ("positions", "fixed", "valid", "adjacency", "end_effector")
    return LinkageBatch(*(np.concatenate([getattr(b, f) for b in batches]) for f in fields))


def augmented(target: np.ndarray, rotations: int) -> np.ndarray:
    """(2 * rotations, M, 2) copies of a normalised target: turned by multiples of
    2 pi / rotations, plain and mirrored (a mirrored copy is also walked backwards, the way a
    mirrored mechanism traces it with its crank still turning counter-clockwise)."""
    copies = []
    for mirror in (False, True):
        for k in range(rotations):
            turned = target @ rotation(2 * np.pi * k / rotations, reflect=mirror).T
            copies.append(turned[::-1] if mirror else turned)
    return np.stack(copies)


def model_proposer(
    model: object, strategy: str, steps: int | None = None, guidance: float | None = None
) -> Proposer:
    """A proposer that samples LinkD (`linkd.sample.sample`) with the given retry strategy."""
    from linkd.sample import sample

    def propose(curves: np.ndarray, per_curve: int, seed: int) -> np.ndarray:
        return sample(model, curves, per_curve, strategy, seed=seed, steps=steps,
                      guidance=guidance).graphs  # fmt: skip

    return propose


def random_proposer() -> Proposer:
    """The curve-blind baseline: curated mechanisms from linkd's random generator, as many as
    LinkD would have sampled; everything after proposal is the same."""
    from linkd.generator import generate

    def propose(curves: np.ndarray, per_curve: int, seed: int) -> np.ndarray:
        return generate(len(curves) * per_curve, np.random.default_rng([seed, 0x52414E44])).graphs

    return propose


def propose(
    proposer: Proposer, target: np.ndarray, count: int, rotations: int, seed: int
) -> np.ndarray:
    """Graph matrices of about `count` designs sampled for the normalised target (M, 2) and its
    augmented copies (as many copies as there are designs to go round, at most), the copies in
    two parts at once (`parallel`), part k from seed `PARTS * seed + k`."""
    curves = augmented(target, rotations) if rotations > 0 else target[None]
    curves = curves[: max(1, count)].astype(np.float32)
    per_curve = -(-max(1, count) // len(curves))
    parts = split(np.arange(len(curves)))
    calls = [partial(proposer, curves[part], per_curve, PARTS * seed + k)
             for k, part in enumerate(parts)]  # fmt: skip
    return np.concatenate(run_parts(calls))


def sub_mechanisms(
    batch: LinkageBatch,
    target: np.ndarray,
    keep: int,
    max_joints: int | None = None,
    motor: np.ndarray | None = None,
) -> LinkageBatch:
    """The `keep` sub-mechanisms of `batch` (in dyadic order, as decoded from graph matrices)
    whose paths look most like the target (of those with at most `max_joints` joints; with a
    `motor` point on the target's curve, as `nearest_shapes` chooses).

    Every moving joint of a valid dyadic linkage traces a curve of its own, and the joints it
    hangs on (its ancestors, down to the crank and the ground) form a smaller valid linkage
    with that joint as end effector. So one sample offers a design per joint, most of them
    with fewer joints (easier to build) than the sample. They are ranked by a shape
    descriptor blind to position, size, rotation, reflection and starting point, so that only
    the best few reach the exact alignment.
    """
    result = validate(batch, keep_motion=True)
    paths = torch.as_tensor(result.motion.paths)  # (B, N, T, 2)
    moving = result.valid[:, None] & batch.valid & ~batch.fixed & (spread(paths).numpy() > MOVES)
    moving[:, :2] = False  # the crank tip only turns in a circle
    rows, joints = np.nonzero(moving)
    if max_joints is not None:
        small = ancestors(batch.adjacency[rows], joints).sum(1) <= max_joints
        rows, joints = rows[small], joints[small]
    if len(rows) == 0:
        return batch  # nothing valid moves: `place` finds no candidate
    if len(rows) > keep:
        curves = resample_closed(paths[rows, joints].double(), 64)
        gap = descriptor(curves) - descriptor(torch.as_tensor(target)[None])
        pivots, want = None, None
        if motor is not None:
            even = resample_closed(torch.as_tensor(target)[None], 64).numpy()  # as the paths
            pivots = own_frame(curves.numpy(), batch.positions[rows, 0])
            want = own_frame(even, np.asarray(motor)[None])
        best = np.sort(nearest_shapes(gap.norm(dim=1), keep, pivots, want))
        rows, joints = rows[best], joints[best]
    return batch.sub_mechanisms(rows, joints)


def descriptor(curves: torch.Tensor) -> torch.Tensor:
    """(B, 2 * HARMONICS) Fourier magnitudes of closed curves (B, M, 2) equally spaced by arc
    length, scaled by the first harmonics: unchanged by translation, scale, rotation, start
    point, and (harmonics k and -k paired in sorted order) reflection and direction."""
    z = torch.fft.fft(torch.complex(curves[..., 0], curves[..., 1]), dim=1).abs()
    k = torch.arange(1, HARMONICS + 1)
    pairs = torch.stack([z[:, k], z[:, -k]], -1).sort(-1).values.flatten(1)
    return pairs / pairs[:, :2].sum(1, keepdim=True).clamp_min(1e-12)


def own_frame(curves: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(B, 2) where each point (B, 2) lies in its closed curve's (B, M, 2, equally spaced by arc
    length) own frame: about its centroid, along its principal axes (least spread first), in
    units of its RMS radius, each coordinate's sign dropped, so that turning or mirroring a
    curve with its point leaves this unchanged."""
    centre = curves.mean(1)
    centred = curves - centre[:, None]
    rms = np.sqrt((centred**2).sum(-1).mean(1)).clip(1e-12)
    _, axes = np.linalg.eigh(np.einsum("bmi,bmj->bij", centred, centred))
    offset = (points - centre) / rms[:, None]
    return np.abs(np.einsum("bi,bij->bj", offset, axes))


def nearest_shapes(
    gap: torch.Tensor, count: int, pivots: np.ndarray | None = None, want: np.ndarray | None = None
) -> np.ndarray:
    """Indices of the `count` smallest shape gaps (E,), smallest first. With `want`, where the
    motor point lies in the target's own frame (`own_frame`, (1, 2)), only the first half so;
    the other half, of the next PINNED_POOL times as many, those whose crank pivot (`pivots`:
    (E, 2), in their paths' own frames) lies nearest it. Turned and scaled about its pivot
    alone, as a motor point pins it, a path can only fit a target whose motor sits where its
    pivot does."""
    pool = min(count * (1 if want is None else PINNED_POOL), len(gap))
    entries = torch.topk(gap, pool, largest=False).indices.numpy()
    if want is None or pool <= count:
        return entries[:count]
    half = count // 2
    off = np.linalg.norm(pivots[entries[half:]].astype(float) - want, axis=1)
    chosen = np.concatenate(
        [np.arange(half), half + np.argsort(off, kind="stable")[: count - half]]
    )
    return entries[np.sort(chosen)]


def place(batch: LinkageBatch, target: np.ndarray, source: np.ndarray | None = None) -> Candidates:
    """Keep the valid linkages of `batch` and move each onto the target by its best similarity,
    in two parts at once (`parallel`); best first. source: (B,) index into SOURCES of each
    linkage (default: all from the model)."""
    source = np.zeros(len(batch), int) if source is None else np.asarray(source)
    parts = split(np.arange(len(batch)))
    if len(parts) < 2:
        return _placed(batch, target, source)
    calls = [partial(_placed, batch.subset(part), target, source[part]) for part in parts]
    both = reduce(merged, run_parts(calls))
    order = np.argsort(both.chamfer, kind="stable")
    return Candidates(both.batch.subset(order), both.chamfer[order], both.source[order])


def _placed(batch: LinkageBatch, target: np.ndarray, source: np.ndarray) -> Candidates:
    """`place` in one process."""
    result = validate(batch, keep_motion=True)
    paths = result.end_effector_paths(batch).astype(np.float64)
    keep = np.flatnonzero(result.valid & (spread(paths) > MOVES))
    batch, paths = batch.subset(keep), paths[keep]
    if len(keep) == 0:
        return Candidates(batch, np.zeros(0), source[keep])
    even = resample_closed(torch.as_tensor(paths), len(target)).numpy()
    similarity, chamfer = align(even, target)
    batch.positions = similarity.apply(batch.positions)
    order = np.argsort(chamfer, kind="stable")
    return Candidates(batch.subset(order), chamfer[order], source[keep][order])
