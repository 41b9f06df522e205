"""The dyads of `kinematics.trace` as one autograd node, for the refinement's gradients.

Through the in-place writes and indexed reads of the joint tables, plain autograd gives every
read a gradient the size of the whole table, zero-filled and summed. This node's backward walks
the steps in reverse instead, touching only each step's own joints, with the dyad's derivative
written out from the terms its forward kept (`kinematics.dyad_terms`).
"""

from __future__ import annotations

import torch

from linkd.kinematics import EPS, dyad_terms, ops_for


class DyadChain(torch.autograd.Function):
    """(xs, ys) (B, N+1, T) joint tables, holding the crank and ground joints; r1sq, r2sq, side
    (B, S) of every plan step; order (S, 3, B) its parents and joint -> the solved tables and
    every step's sin^2 (B, S, T)."""

    @staticmethod
    def forward(ctx, xs, ys, r1sq, r2sq, side, order):
        ops = ops_for(xs)
        xs, ys = xs.clone(), ys.clone()
        b = torch.arange(xs.shape[0], device=xs.device)
        sin2, terms = [], []
        for s, (i, j, k) in enumerate(order):
            x, y, s2, kept = dyad_terms(xs[b, i], ys[b, i], xs[b, j], ys[b, j], r1sq[:, s, None],
                                        r2sq[:, s, None], side[:, s, None], ops)  # fmt: skip
            xs[b, k], ys[b, k] = x, y
            sin2.append(s2)
            terms.append(kept)
        ctx.save_for_backward(r1sq, r2sq, side, order)
        ctx.terms = terms
        return xs, ys, torch.stack(sin2, 1)

    @staticmethod
    def backward(ctx, gxs, gys, gsin2):
        r1sq, r2sq, side, order = ctx.saved_tensors
        gx, gy = gxs.clone(), gys.clone()
        gr1, gr2 = torch.zeros_like(r1sq), torch.zeros_like(r2sq)
        b = torch.arange(gx.shape[0], device=gx.device)
        for s in reversed(range(len(order))):
            i, j, k = order[s]
            gk = gx[b, k], gy[b, k], gsin2[:, s]
            gx[b, k], gy[b, k] = 0.0, 0.0  # written at this step: its earlier value fed nothing
            g = dyad_vjp(ctx.terms[s], r1sq[:, s, None], r2sq[:, s, None], side[:, s, None], *gk)
            gx.index_put_((b, i), g[0], accumulate=True)
            gy.index_put_((b, i), g[1], accumulate=True)
            gx.index_put_((b, j), g[2], accumulate=True)
            gy.index_put_((b, j), g[3], accumulate=True)
            gr1[:, s], gr2[:, s] = g[4], g[5]
        return gx, gy, gr1, gr2, None, None


def dyad_vjp(terms: tuple, r1sq, r2sq, side, gx, gy, gs) -> tuple:
    """Gradients with respect to x1, y1, x2, y2 (B, T) and r1sq, r2sq (B,) of a dyad's
    x = x1 + a dx - h dy, y = y1 + a dy + h dx, sin2 = h2 d2^2 q, given those of x, y, sin2;
    where a = 1/2 + (r1sq - r2sq) / (2 d2), h2 = r1sq / d2 - a^2, h = side sqrt(max(h2, EPS)),
    d2 = max(dx^2 + dy^2, EPS), q = 1 / max(r1sq r2sq, EPS)."""
    dx, dy, d2raw, d2, inv, a, h2, root, h, q = terms
    ga = gx * dx + gy * dy
    gdx = gx * a + gy * h
    gdy = gy * a - gx * h
    gsd = gs * d2
    gh = (gy * dx - gx * dy) * side
    gh2 = gsd * d2 * q + torch.where(h2 > EPS, gh * 0.5 / root, 0.0)
    ga = ga - 2 * a * gh2
    ginv = gh2 * r1sq + ga * (0.5 * (r1sq - r2sq))
    gd2 = torch.where(d2raw > EPS, 2 * gsd * h2 * q - ginv * inv * inv, 0.0)
    gdx, gdy = gdx + 2 * dx * gd2, gdy + 2 * dy * gd2
    gq = torch.where(r1sq * r2sq > EPS, -(gsd * d2 * h2).sum(1, keepdim=True) * q * q, 0.0)
    gr1 = ((gh2 + 0.5 * ga) * inv).sum(1, keepdim=True) + gq * r2sq
    gr2 = (-0.5 * ga * inv).sum(1, keepdim=True) + gq * r1sq
    return gx - gdx, gy - gdy, gdx, gdy, gr1[:, 0], gr2[:, 0]
