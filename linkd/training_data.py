"""Training examples as the model sees them: mechanisms in their curve's frame, conditioning
curves in the form the design pipeline produces, and the augmentations applied to both.

Shared by training (`linkd.train`) and evaluation (`linkd.evaluate`), so neither imports the
other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from linkd.curves import curve_moments
from linkd.graph import VALID, XY

N_POINTS = 200
PATH_RADIUS = 0.25  # RMS radius of the end-effector path in the training frame (at most)
FILL = 0.95  # no joint farther than this from the origin in the training frame


@dataclass
class TrainData:
    graphs: torch.Tensor  # (K, 20, 24) float32
    curves: torch.Tensor  # (K, T, 2) float32, crank-angle samples, normalised
    n_nodes: torch.Tensor  # (K,) int64

    def __len__(self) -> int:
        return len(self.graphs)

    @classmethod
    def load(cls, root: str | Path, split: str) -> TrainData:
        """One split of a data set, its mechanisms moved into their curve's frame."""
        from linkd.dataset import load_split

        part = {k: torch.as_tensor(v) for k, v in load_split(root, split).items()}
        graphs = curve_frame(part["graphs"].float(), part["centre"].float(), part["scale"].float())
        return cls(graphs, part["curves"].float(), part["n_nodes"].long())


def curve_frame(graphs: torch.Tensor, centre: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """Mechanisms re-expressed around their end-effector path: its centroid at the origin, its
    RMS radius PATH_RADIUS, or less where a joint would otherwise lie farther out than FILL.

    The target curve is normalised the same way (centroid 0, fixed size), so the model knows
    where the curve lies among the joints it places, instead of guessing the frame.
    """
    valid = graphs[..., VALID] > 0.5
    rel = (graphs[..., XY] - centre[:, None]) / scale[:, None, None]  # in path radii
    reach = (rel.norm(dim=-1) * valid).amax(1)
    k = torch.clamp(FILL / reach, max=PATH_RADIUS)
    out = graphs.clone()
    out[..., XY] = torch.where(valid[..., None], rel * k[:, None, None], 0.0)
    return out


# ---------------------------------------------------------------------------------------------
# Conditioning curves and augmentation


def resample_closed(curves: torch.Tensor, n: int, offset: torch.Tensor) -> torch.Tensor:
    """(B, M, 2) closed polylines -> (B, n, 2) points equally spaced by arc length, starting a
    fraction `offset` (B,) of the length after the first point."""
    following = curves.roll(-1, 1)
    seg = (following - curves).norm(dim=-1)
    start = seg.cumsum(1) - seg
    total = seg.sum(1, keepdim=True)
    s = (offset[:, None] + torch.arange(n, device=curves.device) / n) % 1 * total
    k = (torch.searchsorted(start, s, right=True) - 1).clamp(0, curves.shape[1] - 1)
    frac = ((s - start.gather(1, k)) / seg.gather(1, k).clamp_min(1e-12)).clamp(0, 1)[..., None]
    pick = k[..., None].expand(-1, -1, 2)
    return curves.gather(1, pick) + frac * (following.gather(1, pick) - curves.gather(1, pick))


def conditioning(curves: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """What the model sees: arc-length resampled, normalised curves; with a generator, from a
    random start and in a random direction."""
    b = len(curves)
    if generator is None:
        offset = torch.zeros(b)
    else:
        reverse = torch.rand(b, generator=generator) < 0.5
        curves = torch.where(reverse[:, None, None], curves.flip(1), curves)
        offset = torch.rand(b, generator=generator)
    points = resample_closed(curves, N_POINTS, offset.to(curves.device))
    centroid, radius = curve_moments(points)
    return (points - centroid[:, None]) / radius[:, None, None]


def augment(graphs, curves, generator, reflect: float, rotate: float):
    """Mirror and rotate mechanisms and curves together; positions are shrunk back into
    [-1, 1] if a rotation pushed them out."""
    b = len(graphs)
    angle = torch.rand(b, generator=generator) * 2 * math.pi
    angle = torch.where(torch.rand(b, generator=generator) < rotate, angle, 0.0)
    mirror = torch.where(torch.rand(b, generator=generator) < reflect, -1.0, 1.0)
    cos, sin = angle.cos(), angle.sin()
    rows = [torch.stack([cos * mirror, -sin], -1), torch.stack([sin * mirror, cos], -1)]
    m = torch.stack(rows, -2).to(graphs.device)
    xy = graphs[..., XY] @ m.transpose(1, 2)
    valid = graphs[..., VALID : VALID + 1] > 0.5
    shrink = (xy.abs() * valid).amax((1, 2)).clamp_min(1.0)
    graphs = graphs.clone()
    graphs[..., XY] = torch.where(valid, xy / shrink[:, None, None], 0.0)
    return graphs, curves @ m.transpose(1, 2)


# ---------------------------------------------------------------------------------------------
# Sub-mechanisms as further examples


def sub_mechanism_examples(
    graphs: torch.Tensor, curves: torch.Tensor, generator: torch.Generator, share: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Replace a `share` of the examples by one of their own sub-mechanisms.

    Every moving joint of a dyadic linkage traces a curve of its own, and the joints it hangs
    on form a smaller valid linkage that ends with it (parents come first, so it is last). A
    graph whose intermediate joint traces a genuine coupler curve (not a circle or arc) gives
    the example (that sub-mechanism, that joint's path), in its own curve's frame: the design
    pipeline offers exactly these to the user, and they teach the model to stop when the last
    joint traces the curve. graphs (B, 20, 24) in their curve's frame, curves (B, T, 2).
    """
    from linkd.batch import LinkageBatch
    from linkd.generator import GeneratorSettings, circle_residual
    from linkd.validator import validate

    batch = LinkageBatch.from_graphs(graphs.numpy())
    result = validate(batch, keep_motion=True)
    paths = np.asarray(result.motion.paths, dtype=np.float64)  # (B, N, T, 2)
    b, n = batch.valid.shape
    centred = paths - paths.mean(2, keepdims=True)
    rms = np.sqrt((centred**2).sum(-1).mean(-1))  # (B, N)
    unit = centred / np.maximum(rms, 1e-12)[..., None, None]
    index = np.arange(n)
    joint = (batch.valid & ~batch.fixed & (index >= 2) & (index < batch.end_effector[:, None])
             & result.valid[:, None] & (rms > 1e-3))  # fmt: skip
    rows, cols = np.nonzero(joint)
    arc = circle_residual(unit[rows, cols]) < GeneratorSettings().arc_tolerance
    joint[rows[arc], cols[arc]] = False
    score = torch.rand((b, n), generator=generator).numpy() * joint
    pick = (torch.rand(b, generator=generator).numpy() < share) & joint.any(1)
    rows, chosen = np.flatnonzero(pick), score.argmax(1)[pick]
    if len(rows) == 0:
        return graphs, curves
    sub = torch.as_tensor(batch.sub_mechanisms(rows, chosen).to_graphs())
    path = paths[rows, chosen]
    centre = torch.as_tensor(path.mean(1), dtype=torch.float32)
    scale = torch.as_tensor(rms[rows, chosen], dtype=torch.float32)
    graphs, curves = graphs.clone(), curves.clone()
    graphs[torch.as_tensor(rows)] = curve_frame(sub, centre, scale)
    curves[torch.as_tensor(rows)] = ((torch.as_tensor(path, dtype=torch.float32) - centre[:, None])
                                     / scale[:, None, None])  # fmt: skip
    return graphs, curves
