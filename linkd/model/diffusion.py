"""Per-node DDPM: noise schedule, the MLP U-Net that predicts a clean node, DDIM sampling.

The network predicts the clean sample x_0 (as logits for the binary entries, coordinates for
the position), which lets each entry have its own loss; DDIM turns the same predictions into a
few-step deterministic sampler whose only randomness is the starting noise.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import torch
from torch import nn


def cosine_alpha_bar(steps: int, s: float = 0.008) -> torch.Tensor:
    """Cumulative signal fraction alpha_bar_t, t = 1..steps, of the cosine schedule."""
    t = torch.arange(steps + 1, dtype=torch.float64) / steps
    f = torch.cos((t + s) / (1 + s) * math.pi / 2) ** 2
    betas = (1 - f[1:] / f[:-1]).clamp(max=0.999)
    return torch.cumprod(1 - betas, 0).float()


def timestep_embedding(t: torch.Tensor, dim: int, max_period: float = 10000.0) -> torch.Tensor:
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, device=t.device) / half)
    args = t.float()[:, None] * freqs[None]
    return torch.cat([args.cos(), args.sin()], -1)


class FiLMBlock(nn.Module):
    """Residual MLP block whose normalised input is scaled and shifted by the condition."""

    def __init__(self, dim_in: int, dim_out: int, cond_dim: int) -> None:
        super().__init__()
        self.norm = nn.LayerNorm(dim_in, elementwise_affine=False)
        self.film = nn.Linear(cond_dim, 2 * dim_in)
        self.mlp = nn.Sequential(
            nn.SiLU(), nn.Linear(dim_in, dim_out), nn.SiLU(), nn.Linear(dim_out, dim_out)
        )
        self.skip = nn.Linear(dim_in, dim_out) if dim_in != dim_out else nn.Identity()

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        scale, shift = self.film(cond).chunk(2, -1)
        return self.skip(x) + self.mlp(self.norm(x) * (1 + scale) + shift)


class DenoiseUNet(nn.Module):
    """MLP U-Net: widths shrink then grow back, with skip connections across, all FiLM-ed by
    the node context h_t plus the diffusion timestep."""

    def __init__(self, features: int, context_dim: int, widths: tuple[int, ...], cond: int) -> None:
        super().__init__()
        self.time = nn.Sequential(nn.Linear(cond, cond), nn.SiLU(), nn.Linear(cond, cond))
        self.context = nn.Linear(context_dim, cond)
        self.inp = nn.Linear(features, widths[0])
        pairs = list(itertools.pairwise(widths))
        self.down = nn.ModuleList(FiLMBlock(a, b, cond) for a, b in pairs)
        self.mid = FiLMBlock(widths[-1], widths[-1], cond)
        self.up = nn.ModuleList(FiLMBlock(2 * b, a, cond) for a, b in reversed(pairs))
        self.out = nn.Sequential(nn.LayerNorm(widths[0]), nn.Linear(widths[0], features))

    def forward(self, x: torch.Tensor, t: torch.Tensor, context: torch.Tensor) -> torch.Tensor:
        time = self.time(timestep_embedding(t, self.context.out_features))
        cond = nn.functional.silu(time + self.context(context))
        h = self.inp(x)
        skips = []
        for block in self.down:
            h = block(h, cond)
            skips.append(h)
        h = self.mid(h, cond)
        for block in self.up:
            h = block(torch.cat([h, skips.pop()], -1), cond)
        return self.out(h)


@torch.no_grad()
def ddim_sample(
    predict_x0: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
    noise: torch.Tensor,
    alpha_bar: torch.Tensor,
    steps: int,
    eta: float = 0.0,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """DDIM from `noise` at t = T down to a clean estimate, in `steps` steps.

    predict_x0(x_t, t) gives the network's clean estimate at integer timesteps t (0-based
    indices into alpha_bar); the final estimate is returned. eta = 0 is deterministic given
    the noise; eta = 1 adds fresh noise at every step like ancestral DDPM sampling.
    """
    total = len(alpha_bar)
    times = torch.linspace(total - 1, 0, steps).round().long().tolist()
    x = noise
    for k, t in enumerate(times):
        x0 = predict_x0(x, torch.full((len(x),), t, dtype=torch.long, device=x.device))
        if k == len(times) - 1:
            return x0
        a, a_next = alpha_bar[t], alpha_bar[times[k + 1]]
        eps = (x - a.sqrt() * x0) / (1 - a).sqrt()
        sigma = eta * ((1 - a_next) / (1 - a) * (1 - a / a_next)).sqrt()
        x = a_next.sqrt() * x0 + (1 - a_next - sigma**2).clamp_min(0).sqrt() * eps
        if eta > 0:
            z = torch.randn(x.shape, generator=generator, device=x.device, dtype=x.dtype)
            x = x + sigma * z
    return x
