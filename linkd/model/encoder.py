"""PointBERT-style curve encoder: a closed 200-point curve -> one embedding E(C).

The curve is cut into overlapping windows of consecutive points (the points are ordered along
the path, so a window is a local patch); a small PointNet shared by all windows embeds each
window's points relative to its centre, a position embedding of the centre is added, and a
transformer encoder with a CLS token mixes the patches. The CLS output is E(C); the patch
outputs come with it for models that also attend to them.
"""

from __future__ import annotations

import torch
from torch import nn


class PointNet(nn.Module):
    """Shared per-point MLP and max-pool: an order-free embedding of one patch."""

    def __init__(self, dim: int, hidden: int = 32) -> None:
        super().__init__()
        self.mlp = nn.Sequential(
            nn.Linear(2, hidden), nn.GELU(), nn.Linear(hidden, 2 * hidden), nn.GELU()
        )
        self.out = nn.Linear(2 * hidden, dim)

    def forward(self, points: torch.Tensor) -> torch.Tensor:  # (..., P, 2) -> (..., dim)
        return self.out(self.mlp(points).amax(-2))


class CurveEncoder(nn.Module):
    def __init__(self, dim: int, layers: int, heads: int, patch: int = 10, stride: int = 8) -> None:
        super().__init__()
        self.patch, self.stride = patch, stride
        self.pointnet = PointNet(dim)
        self.centre = nn.Sequential(nn.Linear(2, dim), nn.GELU(), nn.Linear(dim, dim))
        self.cls = nn.Parameter(torch.zeros(1, 1, dim))
        layer = nn.TransformerEncoderLayer(
            dim, heads, 4 * dim, dropout=0.0, activation="gelu", batch_first=True, norm_first=True
        )
        self.transformer = nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(dim)

    def patches(self, curves: torch.Tensor) -> torch.Tensor:
        """(B, N, 2) closed curves -> (B, N // stride, patch, 2) windows, wrapping around."""
        n = curves.shape[1]
        start = torch.arange(0, n, self.stride, device=curves.device)
        index = (start[:, None] + torch.arange(self.patch, device=curves.device)) % n
        return curves[:, index]

    def forward(self, curves: torch.Tensor) -> torch.Tensor:
        windows = self.patches(curves)
        centres = windows.mean(-2)
        tokens = self.pointnet(windows - centres[..., None, :]) + self.centre(centres)
        tokens = torch.cat([self.cls.expand(len(curves), -1, -1), tokens], 1)
        return self.norm(self.transformer(tokens))  # (B, 1 + patches, dim), E(C) first
