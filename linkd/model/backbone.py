"""Node embedding and the causal transformer that turns a partial graph into h_t.

Sequence position 0 holds a learned start token and position k + 1 holds node k, so the output
at position t has seen exactly nodes < t: it is the context h_t from which node t is sampled.
Blocks are DiT blocks: adaLN (scale, shift and gate from the curve embedding, zero-initialised),
causal self-attention and a feed-forward network; optionally (not in the paper) also
cross-attention from the nodes to the curve encoder's patch tokens. During sampling the blocks
keep a key/value cache, so adding a node costs one token, not the whole prefix again.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from linkd.graph import ADJ, MAX_NODES, TYPE, VALID, XY


class FourierFeatures(nn.Module):
    """Learned Fourier features of (x, y): sin and cos of learned frequencies, plus x and y."""

    def __init__(self, dim: int, count: int = 32, scale: float = 2.0) -> None:
        super().__init__()
        self.freq = nn.Parameter(torch.randn(2, count) * scale)
        self.out = nn.Linear(2 + 2 * count, dim)

    def forward(self, xy: torch.Tensor) -> torch.Tensor:
        phase = 2 * math.pi * xy @ self.freq
        return self.out(torch.cat([xy, phase.sin(), phase.cos()], -1))


class NodeEmbedding(nn.Module):
    """Graph-matrix rows -> tokens: validity, type, position and adjacency embeddings, mixed."""

    def __init__(self, dim: int) -> None:
        super().__init__()
        self.validity = nn.Embedding(2, dim)
        self.kind = nn.Embedding(3, dim)  # padding, moving, ground
        self.position = FourierFeatures(dim)
        self.adjacency = nn.Linear(3 * MAX_NODES, dim)  # one-hot of -1 / 0 / 1 per entry
        self.mixer = nn.Sequential(nn.Linear(4 * dim, dim), nn.GELU(), nn.Linear(dim, dim))

    def forward(self, rows: torch.Tensor) -> torch.Tensor:  # (B, L, 24) -> (B, L, dim)
        valid = (rows[..., VALID] > 0.5).long()
        kind = rows[..., TYPE].round().long().clamp(-1, 1) + 1
        adj = F.one_hot(rows[..., ADJ].round().long().clamp(-1, 1) + 1, 3).flatten(-2)
        parts = [
            self.validity(valid),
            self.kind(kind),
            self.position(rows[..., XY]),
            self.adjacency(adj.to(rows.dtype)),
        ]
        return self.mixer(torch.cat(parts, -1))


def modulate(x: torch.Tensor, shift: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    return x * (1 + scale[:, None]) + shift[:, None]


class CrossAttention(nn.Module):
    """Node tokens attend to the curve's patch tokens (their keys and values cached)."""

    def __init__(self, dim: int, heads: int) -> None:
        super().__init__()
        self.heads = heads
        self.q = nn.Linear(dim, dim)
        self.kv = nn.Linear(dim, 2 * dim)
        self.proj = nn.Linear(dim, dim)

    def forward(self, x: torch.Tensor, curve: torch.Tensor, cache: dict | None) -> torch.Tensor:
        b, n, d = x.shape
        if cache is not None and "curve_k" in cache:
            k, v = cache["curve_k"], cache["curve_v"]
        else:
            kv = self.kv(curve).view(b, -1, 2, self.heads, d // self.heads)
            k, v = kv.permute(2, 0, 3, 1, 4)
            if cache is not None:
                cache["curve_k"], cache["curve_v"] = k, v
        q = self.q(x).view(b, n, self.heads, d // self.heads).transpose(1, 2)
        y = F.scaled_dot_product_attention(q, k, v)
        return self.proj(y.transpose(1, 2).reshape(b, n, d))


class Block(nn.Module):
    """DiT block: adaLN-Zero conditioning on E(C), causal self-attention, optionally
    cross-attention to the curve's patch tokens, feed-forward network."""

    def __init__(self, dim: int, heads: int, cross: bool) -> None:
        super().__init__()
        self.heads = heads
        self.norm1 = nn.LayerNorm(dim, elementwise_affine=False)
        self.qkv = nn.Linear(dim, 3 * dim)
        self.proj = nn.Linear(dim, dim)
        self.norm2 = nn.LayerNorm(dim, elementwise_affine=False)
        self.mlp = nn.Sequential(nn.Linear(dim, 4 * dim), nn.GELU(), nn.Linear(4 * dim, dim))
        self.cross = CrossAttention(dim, heads) if cross else None
        self.norm3 = nn.LayerNorm(dim, elementwise_affine=False) if cross else None
        self.ada = nn.Sequential(nn.SiLU(), nn.Linear(dim, (9 if cross else 6) * dim))
        nn.init.zeros_(self.ada[1].weight)
        nn.init.zeros_(self.ada[1].bias)

    def attention(self, x: torch.Tensor, cache: dict | None) -> torch.Tensor:
        b, n, d = x.shape
        q, k, v = self.qkv(x).view(b, n, 3, self.heads, d // self.heads).permute(2, 0, 3, 1, 4)
        if cache is not None:
            if "k" in cache:
                k, v = torch.cat([cache["k"], k], 2), torch.cat([cache["v"], v], 2)
            cache["k"], cache["v"] = k, v
        # With a cache the new token(s) come last, so a plain causal mask would be misaligned;
        # incremental decoding adds one token at a time, which may attend to everything.
        causal = cache is None and n > 1
        y = F.scaled_dot_product_attention(q, k, v, is_causal=causal)
        return self.proj(y.transpose(1, 2).reshape(b, n, d))

    def forward(self, x: torch.Tensor, curve: torch.Tensor, cache: dict | None = None):
        """x (B, L, dim) node tokens; curve (B, 1 + P, dim): E(C), then the patch tokens."""
        if cache is not None and "mod" in cache:
            mod = cache["mod"]
        else:
            mod = self.ada(curve[:, 0]).chunk(9 if self.cross else 6, -1)
            if cache is not None:
                cache["mod"] = mod
        shift1, scale1, gate1, shift2, scale2, gate2 = mod[:6]
        x = x + gate1[:, None] * self.attention(modulate(self.norm1(x), shift1, scale1), cache)
        if self.cross is not None:
            shift3, scale3, gate3 = mod[6:]
            y = self.cross(modulate(self.norm3(x), shift3, scale3), curve[:, 1:], cache)
            x = x + gate3[:, None] * y
        return x + gate2[:, None] * self.mlp(modulate(self.norm2(x), shift2, scale2))


class CausalBackbone(nn.Module):
    """Partial graph + curve encoding -> one context vector h_t per next node."""

    def __init__(self, dim: int, layers: int, heads: int, cross: bool = False) -> None:
        super().__init__()
        self.embed = NodeEmbedding(dim)
        self.start = nn.Parameter(torch.zeros(1, 1, dim))
        self.index = nn.Parameter(torch.zeros(1, MAX_NODES, dim))
        nn.init.normal_(self.index, std=0.02)
        nn.init.normal_(self.start, std=0.02)
        self.blocks = nn.ModuleList(Block(dim, heads, cross) for _ in range(layers))
        self.norm = nn.LayerNorm(dim, elementwise_affine=False)
        self.final = nn.Sequential(nn.SiLU(), nn.Linear(dim, 2 * dim))

    def tokens(self, rows: torch.Tensor, offset: int) -> torch.Tensor:
        """Start token (when offset is 0) then node embeddings, plus sequence-index embeddings."""
        x = self.embed(rows) if rows.shape[1] else rows.new_zeros(len(rows), 0, self.start.shape[2])
        if offset == 0:
            x = torch.cat([self.start.expand(len(rows), -1, -1), x], 1)
        return x + self.index[:, offset : offset + x.shape[1]]

    def forward(
        self, rows: torch.Tensor, curve: torch.Tensor, cache: list[dict] | None = None
    ) -> torch.Tensor:
        """Contexts for the positions after `rows`, given the curve encoding (B, 1 + P, dim).

        Without a cache, rows (B, L, 24) are nodes 0..L-1 and the result (B, L + 1, dim) holds
        h_0..h_L. With a cache (one dict per block, empty at first) rows are only the nodes not
        seen yet: (B, 0, 24) at the start, then one node per call, each giving the next h.
        """
        offset = cache[0]["k"].shape[2] if cache and "k" in cache[0] else 0
        x = self.tokens(rows, offset)
        for k, block in enumerate(self.blocks):
            x = block(x, curve, None if cache is None else cache[k])
        shift, scale = self.final(curve[:, 0]).chunk(2, -1)
        return modulate(self.norm(x), shift, scale)
