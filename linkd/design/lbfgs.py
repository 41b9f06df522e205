"""Batched L-BFGS: many independent minimisations at once, one line search per problem.

torch's own L-BFGS minimises one function; summing independent problems into it would make them
share a step length and a curvature model. Here every row of the batch keeps its own history,
its own step and its own backtracking (Armijo) line search, while each evaluation runs all the
rows still searching at once, each at its own trial step: a row whose step is accepted takes
its next direction while another tries a shorter step (a line search in lockstep would run
each evaluation's tries one after the other, mostly for a few rows, and evaluations are mostly
fixed overhead at the batch sizes used). A line search gets a few trials at most: a row that
finds no decrease by then forgets its history and starts again from a shorter steepest-descent
step.
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
    """Minimise the B independent functions of `evaluate` from x (B, D); returns x and the
    iterations run, or all of them where every row converged sooner: fewer than asked means the
    deadline cut the minimisation short.

    iterations: evaluations of every row still searching, each row trying one step of its own
    line search (a row whose first step is accepted goes on with its next direction).
    first_step: the length of a steepest-descent step (the first one, or after a reset).
    deadline: a `time.monotonic()` value after which no new iteration starts.
    on_iteration: called with the number of iterations done after each one (for progress).
    """
    x = x.clone()
    state = _State(x, history, first_step)
    every = torch.arange(len(x))
    f, g = evaluate(x, every)
    state.aim(every, g)
    if not state.active.any():
        return x, iterations
    done = 0
    for done in range(1, iterations + 1):
        rows = every[state.active]
        step, direction, slope = state.step[rows], state.direction[rows], state.slope[rows]
        trial = x[rows] + step[:, None] * direction
        f_try, g_try = evaluate(trial, rows)
        bound = f[rows] + ARMIJO * step * slope + 1e-6 * f[rows].abs()  # float32 rounding in f
        accept = torch.isfinite(f_try) & (f_try <= bound)
        good = rows[accept]
        state.remember(good, trial[accept] - x[good], g_try[accept] - g[good])
        x[good], f[good], g[good] = trial[accept], f_try[accept], g_try[accept]
        # A failed trial: the next is the minimum of the parabola through f(0), f'(0) and
        # f(step), kept within [0.1, 0.5] of the step that failed.
        t, f0, d0 = step[~accept], f[rows[~accept]], slope[~accept]
        rise = torch.nan_to_num(f_try[~accept] - f0 - d0 * t, nan=torch.inf).clamp_min(1e-30)
        given_up = state.shorten(rows[~accept], t * (-d0 * t / (2 * rise)).clamp(0.1, 0.5))
        state.aim(torch.cat([good, given_up]), g)
        if on_iteration is not None:
            on_iteration(done)
        if not state.active.any():
            return x, iterations
        if deadline is not None and time.monotonic() > deadline:
            break
    return x, done


class _State:
    """Every row's L-BFGS history and current line search."""

    def __init__(self, x: torch.Tensor, history: int, first_step: float):
        bsz, dim = x.shape
        self.first_step = first_step
        self.s = x.new_zeros(bsz, history, dim)
        self.y = x.new_zeros(bsz, history, dim)
        self.rho = x.new_zeros(bsz, history)  # 1 / (s . y); 0 marks an empty slot
        self.plain = torch.full((bsz,), first_step, dtype=x.dtype)  # steepest-descent length
        self.direction = torch.zeros_like(x)
        self.slope = x.new_zeros(bsz)  # of f along the direction
        self.step = x.new_ones(bsz)  # the next trial's multiple of the direction
        self.tries = torch.zeros(bsz, dtype=torch.long)  # trials along this direction so far
        self.fresh = torch.ones(bsz, dtype=torch.bool)  # the direction is steepest descent
        self.active = torch.ones(bsz, dtype=torch.bool)  # still searching

    def remember(self, rows: torch.Tensor, s: torch.Tensor, y: torch.Tensor) -> None:
        """Rows whose trial step s was accepted, changing the gradient by y: a longer
        steepest-descent step next time if this was one, and the pair where it curves up."""
        sy = (s * y).sum(1)
        new = sy > 1e-10 * s.norm(dim=1) * y.norm(dim=1)
        kept = rows[new]
        for table in (self.s, self.y, self.rho):
            table[kept] = torch.roll(table[kept], 1, 1)
        self.s[kept, 0], self.y[kept, 0], self.rho[kept, 0] = s[new], y[new], 1 / sy[new]
        grown = (self.plain[rows] * 2).clamp_max(10 * self.first_step)
        self.plain[rows] = torch.where(self.fresh[rows], grown, self.plain[rows])

    def shorten(self, rows: torch.Tensor, step: torch.Tensor) -> torch.Tensor:
        """Rows whose trial failed try `step` next; those out of tries forget their history (a
        shorter steepest-descent step if that failed too) and are returned, to start again."""
        self.step[rows] = step
        self.tries[rows] += 1
        out = rows[self.tries[rows] >= TRIES]
        self.plain[out] = torch.where(self.fresh[out], self.plain[out] * 0.1, self.plain[out])
        self.rho[out] = 0
        return out

    def aim(self, rows: torch.Tensor, g: torch.Tensor) -> None:
        """A new search direction for `rows` from their gradients g (all rows) and histories."""
        rho = self.rho[rows]
        d = _direction(g[rows], self.s[rows], self.y[rows], rho, self.plain[rows])
        self.direction[rows], self.slope[rows] = d, (g[rows] * d).sum(1)
        self.fresh[rows] = (rho == 0).all(1)
        self.step[rows], self.tries[rows] = 1.0, 0
        self.active[rows] = (self.plain[rows] >= SHORTEST) & (g[rows].norm(dim=1) > FLAT)


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
