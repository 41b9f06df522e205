"""An atlas of random mechanisms with every moving joint's path indexed by its shape.

Proposing designs for a drawn shape by sampling is slow and narrow; looking one up is fast and
wide. The atlas holds tens of thousands of curated random mechanisms (linkd's generator, seeded)
and, for every moving joint of each, a shape descriptor of that joint's path, blind to position,
size, rotation, reflection, direction and starting point (`propose.descriptor`). A query finds
the paths nearest the target's descriptor in milliseconds and returns the sub-mechanisms that
trace them (the joint with the joints it hangs on), ready to be placed on the target and refined
next to the model's proposals.

Built by `linkd atlas build` (deterministic for a seed, whatever the number of workers: every
chunk of mechanisms has its own seed) and stored as a compressed .npz: positions as float16 (the
paths are traced from the rounded positions, so descriptors and mechanisms agree), topologies as
packed bits, descriptors as one byte per value.
"""

from __future__ import annotations

import importlib.resources
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from linkd.batch import LinkageBatch
from linkd.errors import InputError
from linkd.generator import GeneratorSettings, circle_residual, generate
from linkd.graph import MAX_NODES
from linkd.sample import MOVES, spread
from linkd.validator import validate

from .propose import descriptor, nearest_shapes, own_frame
from .refine import resample_closed

FORMAT = "linkd-atlas/2"
DEFAULT_PATH = Path(str(importlib.resources.files("linkd.assets") / "atlas.npz"))  # shipped
CHUNK = 2000  # mechanisms generated per seeded job
ANGLES = 128  # crank angles each path is traced at for its descriptor
SHAPE_POINTS = 64  # points by arc length the descriptor is taken from
ARC_TOLERANCE = 0.01  # paths this close to a circle or arc are left out (circle_residual)
FAR = 1000.0  # pivots further than this many RMS radii from their path are stored as this far
_UPPER = np.triu_indices(MAX_NODES, 1)


@dataclass
class Atlas:
    """K mechanisms (padded to MAX_NODES joints) and E indexed joint paths."""

    positions: np.ndarray  # (K, N, 2) float16, assembly pose in the box [-1, 1]^2
    fixed: np.ndarray  # (K, ceil(N / 8)) uint8, packed ground flags
    links: np.ndarray  # (K, ceil(N (N - 1) / 16)) uint8, packed upper triangle of adjacency
    n_nodes: np.ndarray  # (K,) uint8
    mechanism: np.ndarray  # (E,) uint32, the mechanism each path belongs to
    joint: np.ndarray  # (E,) uint8, the joint that traces it
    shape: np.ndarray  # (E, D) uint8, quantised descriptor (`quantise`)
    pivot: np.ndarray  # (E, 2) float16, the crank pivot in the path's own frame (`own_frame`)
    meta: dict = field(default_factory=dict)
    _codes: torch.Tensor | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.mechanism)

    def batch(self, rows: np.ndarray) -> LinkageBatch:
        """The mechanisms `rows` as a linkage batch (end effector: the last joint)."""
        n = MAX_NODES
        count = len(rows)
        valid = np.arange(n) < self.n_nodes[rows, None].astype(int)
        fixed = np.unpackbits(self.fixed[rows], axis=1, count=n).astype(bool) & valid
        upper = np.unpackbits(self.links[rows], axis=1, count=len(_UPPER[0])).astype(bool)
        adjacency = np.zeros((count, n, n), bool)
        adjacency[:, _UPPER[0], _UPPER[1]] = upper
        adjacency |= adjacency.transpose(0, 2, 1)
        positions = self.positions[rows].astype(np.float64)
        return LinkageBatch(positions, fixed, valid, adjacency, valid.sum(1) - 1)

    def nearest(
        self, target: np.ndarray, count: int, motor: np.ndarray | None = None
    ) -> np.ndarray:
        """Indices of the `count` paths whose descriptors are nearest the target's, nearest
        first (with a `motor` point, as `propose.nearest_shapes` chooses). target: (M, 2)
        closed curve."""
        if self._codes is None:
            self._codes = torch.as_tensor(self.shape).float()
        curve = torch.as_tensor(np.ascontiguousarray(target), dtype=torch.float64)[None]
        even = resample_closed(curve, SHAPE_POINTS)
        query = torch.as_tensor(quantise(descriptor(even).numpy())).float()
        gap = torch.cdist(query, self._codes)[0]
        want = None if motor is None else own_frame(even.numpy(), np.asarray(motor)[None])
        return nearest_shapes(gap, count, self.pivot, want)

    def query(
        self, target: np.ndarray, count: int, motor: np.ndarray | None = None
    ) -> LinkageBatch:
        """The sub-mechanisms tracing the `count` paths most like the target (with a `motor`
        point: `nearest`'s choice), nearest first."""
        entries = self.nearest(target, count, motor)
        rows, index = np.unique(self.mechanism[entries], return_inverse=True)
        whole = self.batch(rows).subset(index.reshape(-1))
        return whole.sub_mechanisms(np.arange(len(entries)), self.joint[entries].astype(int))

    def save(self, path: str | Path) -> None:
        """Write the atlas as a compressed .npz, whole or not at all."""
        path = Path(path)
        if not path.parent.is_dir():
            raise InputError(f"{path}: folder {path.parent} does not exist")
        arrays = {k: getattr(self, k) for k in _ARRAYS}
        scratch = path.with_name(f".{path.name}.partial.npz")
        try:
            np.savez_compressed(scratch, meta=np.array(json.dumps(self.meta)), **arrays)
            os.replace(scratch, path)
        finally:
            scratch.unlink(missing_ok=True)


_ARRAYS = ("positions", "fixed", "links", "n_nodes", "mechanism", "joint", "shape", "pivot")


def quantise(descriptors: np.ndarray) -> np.ndarray:
    """uint8 codes of descriptors (values in [0, ~1]): square roots, so that the small high
    harmonics keep their resolution, in steps of 1/255."""
    return np.clip(np.rint(np.sqrt(np.clip(descriptors, 0, None)) * 255), 0, 255).astype(np.uint8)


def load(path: str | Path | None = None) -> Atlas:
    """The atlas at `path` (default: the one shipped in linkd's assets)."""
    path = Path(path) if path else DEFAULT_PATH
    if not path.is_file():
        raise InputError(f"{path}: {'is a folder, not' if path.is_dir() else 'no such'} atlas")
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            if meta.get("format") != FORMAT:
                raise InputError(f"{path}: a {meta.get('format')} file, not {FORMAT} (build it "
                                 "again with linkd atlas build)")  # fmt: skip
            arrays = {k: data[k] for k in _ARRAYS}
    except (OSError, KeyError, ValueError, AttributeError):
        raise InputError(f"{path}: not a linkd atlas (a .npz of linkd atlas build)") from None
    return Atlas(**arrays, meta=meta)


def build_chunk(job: tuple[int, int, int]) -> Atlas:
    """The atlas part of one chunk: `count` mechanisms from the seed (seed, k)."""
    k, count, seed = job
    settings = GeneratorSettings()
    graphs = generate(count, np.random.default_rng((seed, k)), settings).graphs
    batch = LinkageBatch.from_graphs(graphs)
    batch.positions = batch.positions.astype(np.float16).astype(np.float64)
    result = validate(batch, n_angles=ANGLES, keep_motion=True)
    paths = np.stack([result.motion.x, result.motion.y], -1)  # (K, N, T, 2)
    moving = result.valid[:, None] & batch.valid & ~batch.fixed & (spread(paths) > MOVES)
    moving[:, :2] = False  # the crank tip only turns in a circle
    rows, joints = np.nonzero(moving)
    curves = paths[rows, joints].astype(np.float64)
    centred = curves - curves.mean(1, keepdims=True)
    rms = np.sqrt((centred**2).sum(-1).mean(1))
    arc = circle_residual(centred / np.maximum(rms, 1e-12)[:, None, None]) < ARC_TOLERANCE
    rows, joints, curves = rows[~arc], joints[~arc], curves[~arc]
    even = resample_closed(torch.as_tensor(curves), SHAPE_POINTS)
    pivot = own_frame(even.numpy(), batch.positions[rows, 0])
    used, mechanism = np.unique(rows, return_inverse=True)
    part = batch.subset(used)
    upper = part.adjacency[:, _UPPER[0], _UPPER[1]]
    return Atlas(
        part.positions.astype(np.float16),
        np.packbits(part.fixed, axis=1),
        np.packbits(upper, axis=1),
        part.valid.sum(1).astype(np.uint8),
        mechanism.reshape(-1).astype(np.uint32),
        joints.astype(np.uint8),
        quantise(descriptor(even).numpy()),
        pivot.clip(max=FAR).astype(np.float16),
    )


def build(count: int, seed: int = 0, workers: int = 1) -> Atlas:
    """An atlas of `count` random curated mechanisms (before dropping those that no longer
    validate once rounded), with a progress bar on a terminal."""
    from linkd.dataset import _run

    sizes = [min(CHUNK, count - start) for start in range(0, count, CHUNK)]
    jobs = [(k, n, seed) for k, n in enumerate(sizes)]
    parts = _run(jobs, build_chunk, sizes, workers, "building the atlas")
    offsets = np.cumsum([0] + [len(p.positions) for p in parts])
    meta = {"format": FORMAT, "count": count, "seed": seed, "angles": ANGLES,
            "shape_points": SHAPE_POINTS, "mechanisms": int(offsets[-1]),
            "paths": int(sum(len(p) for p in parts))}  # fmt: skip
    joined = {k: np.concatenate([getattr(p, k) for p in parts]) for k in _ARRAYS}
    joined["mechanism"] = np.concatenate(
        [p.mechanism + np.uint32(first) for p, first in zip(parts, offsets)]
    )
    return Atlas(**joined, meta=meta)
