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

import numpy as np
import torch

from linkd.align import align
from linkd.batch import LinkageBatch
from linkd.design.refine import resample_closed
from linkd.geometry import rotation
from linkd.validator import validate

# (conditioning curves (C, 200, 2), samples per curve, seed) -> graph matrices (C * S, 20, 24)
Proposer = Callable[[np.ndarray, int, int], np.ndarray]
MOVES = 1e-6  # an end effector whose path spreads less than this (graph units) stands still


@dataclass
class Candidates:
    """Valid candidate mechanisms placed on the target, best first."""

    batch: LinkageBatch  # positions in the target's normalised frame
    chamfer: np.ndarray  # (K,) Chamfer distance of each placed path to the target

    def __len__(self) -> int:
        return len(self.chamfer)


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


def model_proposer(model: object, strategy: str, steps: int | None = None) -> Proposer:
    """A proposer that samples LinkD (`linkd.sample.sample`) with the given retry strategy."""
    from linkd.sample import sample

    def propose(curves: np.ndarray, per_curve: int, seed: int) -> np.ndarray:
        return sample(model, curves, per_curve, strategy, seed=seed, steps=steps).graphs

    return propose


def propose(
    proposer: Proposer, target: np.ndarray, count: int, rotations: int, seed: int
) -> np.ndarray:
    """Graph matrices of about `count` designs sampled for the normalised target (M, 2) and its
    augmented copies (as many copies as there are designs to go round, at most)."""
    curves = augmented(target, rotations) if rotations > 0 else target[None]
    curves = curves[: max(1, count)]
    per_curve = -(-max(1, count) // len(curves))
    return proposer(curves.astype(np.float32), per_curve, seed)


def place(batch: LinkageBatch, target: np.ndarray) -> Candidates:
    """Keep the valid linkages of `batch` and move each onto the target by its best similarity."""
    result = validate(batch, keep_motion=True)
    paths = result.end_effector_paths(batch).astype(np.float64)
    spread = np.sqrt(((paths - paths.mean(1, keepdims=True)) ** 2).sum(-1).mean(1))
    keep = np.flatnonzero(result.valid & (spread > MOVES))
    batch, paths = batch.subset(keep), paths[keep]
    if len(keep) == 0:
        return Candidates(batch, np.zeros(0))
    even = resample_closed(torch.as_tensor(paths), len(target)).numpy()
    similarity, chamfer = align(even, target)
    batch.positions = similarity.apply(batch.positions)
    order = np.argsort(chamfer, kind="stable")
    return Candidates(batch.subset(order), chamfer[order])
