"""Batched L-BFGS: many independent minimisations at once, one line search per problem.

torch's own L-BFGS minimises one function; summing independent problems into it would make them
share a step length and a curvature model. Here every row of the batch keeps its own history,
its own step and its own backtracking (Armijo) line search, while each evaluation runs all the
rows still searching at once. Evaluations are mostly fixed overhead at the batch sizes used, so
a line search gets a few evaluations at most: a row that finds no decrease by then stays put,
forgets its history and starts again from a shorter steepest-descent step.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import torch

# (x (k, D), rows (k,) of the batch) -> (f (k,), gradient (k, D))
Evaluate = Callable[[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]

ARMIJO = 1e-4
TRIES = 3  # evaluations per line search
SHORTEST = 1e-6  # a row whose steepest-descent step has shrunk below this has converged
FLAT = 1e-10  # so has a row whose gradient is this small


def minimise(
    evaluate: Evaluate,
    x: torch.Tensor,
    iterations: int,
    history: int = 10,
    first_step: float = 0.01,
    deadline: float | None = None,
    on_iteration: Callable[[int], None] | None = None,
) -> tuple[torch.Tensor, int]:
    """Minimise the B independent functions of `evaluate` from x (B, D); returns (x, iterations).

    first_step: the length of a steepest-descent step (the first one, or after a reset).
    deadline: a `time.monotonic()` value after which no new iteration starts.
    on_iteration: called with the number of iterations done after each one (for progress).
    """
    bsz, dim = x.shape
    s_hist = x.new_zeros(bsz, history, dim)
    y_hist = x.new_zeros(bsz, history, dim)
    rho = x.new_zeros(bsz, history)  # 1 / (s . y); 0 marks an empty slot
    plain = torch.full((bsz,), first_step, dtype=x.dtype)  # steepest-descent step length
    every = torch.arange(bsz)
    f, g = evaluate(x, every)
    done = 0
    for done in range(1, iterations + 1):
        active = (plain >= SHORTEST) & (g.norm(dim=1) > FLAT)
        fresh = (rho == 0).all(1)  # no history: this step is steepest descent
        direction = _direction(g, s_hist, y_hist, rho, plain)
        slope = (g * direction).sum(1)
        tolerance = 1e-6 * f.abs()  # float32 rounding in f
        step = torch.ones_like(f)
        pending = active.clone()
        x_new, f_new, g_new = x.clone(), f.clone(), g.clone()
        for _ in range(TRIES):
            rows = every[pending]
            if len(rows) == 0:
                break
            trial = x[rows] + step[rows, None] * direction[rows]
            f_try, g_try = evaluate(trial, rows)
            bound = f[rows] + ARMIJO * step[rows] * slope[rows] + tolerance[rows]
            accept = torch.isfinite(f_try) & (f_try <= bound)
            good = rows[accept]
            x_new[good], f_new[good], g_new[good] = trial[accept], f_try[accept], g_try[accept]
            pending[good] = False
            # Next step: the minimum of the parabola through f(0), f'(0) and f(step), kept
            # within [0.1, 0.5] of the step that failed.
            t, f0, d0 = step[rows], f[rows], slope[rows]
            rise = torch.nan_to_num(f_try - f0 - d0 * t, nan=torch.inf).clamp_min(1e-30)
            shrink = (-d0 * t / (2 * rise)).clamp(0.1, 0.5)
            step[rows] = torch.where(accept, t, t * shrink)
        moved = active & ~pending
        s, y = x_new - x, g_new - g
        sy = (s * y).sum(1)
        keep = moved & (sy > 1e-10 * s.norm(dim=1) * y.norm(dim=1))
        s_hist[keep] = torch.roll(s_hist[keep], 1, 1)
        y_hist[keep] = torch.roll(y_hist[keep], 1, 1)
        rho[keep] = torch.roll(rho[keep], 1, 1)
        s_hist[keep, 0], y_hist[keep, 0], rho[keep, 0] = s[keep], y[keep], 1 / sy[keep]
        failed = active & pending
        plain = torch.where(failed & fresh, plain * 0.1, plain)  # steepest descent failed too
        plain = torch.where(moved & fresh, (plain * 2).clamp_max(10 * first_step), plain)
        rho[failed] = 0
        x, f, g = x_new, f_new, g_new
        if on_iteration is not None:
            on_iteration(done)
        if not active.any() or (deadline is not None and time.monotonic() > deadline):
            break
    return x, done


def _direction(
    g: torch.Tensor, s: torch.Tensor, y: torch.Tensor, rho: torch.Tensor, plain: torch.Tensor
) -> torch.Tensor:
    """-H g by the two-loop recursion (slot 0 is the newest pair); steepest descent of length
    `plain` where a row has no history or the recursion points uphill."""
    q = g.clone()
    alphas = []
    for i in range(s.shape[1]):
        a = rho[:, i] * (s[:, i] * q).sum(1)
        q = q - a[:, None] * y[:, i]
        alphas.append(a)
    used = rho[:, 0] > 0
    gamma = 1 / (rho[:, 0] * (y[:, 0] * y[:, 0]).sum(1)).clamp_min(1e-30)
    r = q * torch.where(used, gamma, 0)[:, None]
    for i in reversed(range(s.shape[1])):
        b = rho[:, i] * (y[:, i] * r).sum(1)
        r = r + (alphas[i] - b)[:, None] * s[:, i]
    steepest = -g * (plain / g.norm(dim=1).clamp_min(1e-30))[:, None]
    uphill = ~used | ((-r * g).sum(1) >= 0)
    return torch.where(uphill[:, None], steepest, -r)
