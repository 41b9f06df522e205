"""The curve's principal-axis frame, in which a canonical model reads curves and places joints.

A normalised curve (centroid 0, RMS radius 1) still comes in any orientation, and a small model
spends much of what it can learn on turning its answer with the curve. Turning every curve (and
its mechanism with it) onto the curve's principal axis first leaves only the shape to learn:
the axis of largest spread becomes x, pointing to the side the curve leans to (third moment
positive). Reflection is not removed (a mirrored mechanism is a different design).
"""

from __future__ import annotations

import torch

from linkd.graph import VALID, XY


def principal_turn(curves: torch.Tensor) -> torch.Tensor:
    """(B, 2, 2) rotations R taking centred curves (B, M, 2) to their principal frame: the rows
    of R are the frame's axes, so a point p goes to R p (a row of points P to P R^T)."""
    points = curves.double()
    points = points - points.mean(1, keepdim=True)
    cov = points.transpose(1, 2) @ points / points.shape[1]
    axis = torch.linalg.eigh(cov).eigenvectors[..., :, 1]  # (B, 2), largest eigenvalue's
    lean = ((points @ axis[..., None]) ** 3).mean((1, 2))
    axis = torch.where(lean[:, None] < 0, -axis, axis)
    normal = torch.stack([-axis[:, 1], axis[:, 0]], -1)
    return torch.stack([axis, normal], 1).to(curves.dtype)


def turned(graphs: torch.Tensor, turn: torch.Tensor) -> torch.Tensor:
    """(B, N, 24) graph matrices with their valid joints' positions turned by `turn` (B, 2, 2)."""
    valid = graphs[..., VALID : VALID + 1] > 0.5
    out = graphs.clone()
    out[..., XY] = torch.where(valid, graphs[..., XY] @ turn.transpose(1, 2), graphs[..., XY])
    return out
