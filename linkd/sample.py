"""Sample linkages from LinkD for target curves: one-shot, graph-level or node-level retry.

All samples of all curves grow together, one node per step, and only the samples still growing
are computed. Node-level retry checks every proposed node at once with the incremental
validator (`check_new_node`, one dyad each, the accepted prefix's joint paths kept) and
resamples only the nodes that fail, up to `retries` times, keeping the best proposal seen; a
node that fails every one ends its graph after the last earlier joint that moves (every prefix
of a valid linkage is one).
"""

from __future__ import annotations

import importlib.resources
import pickle
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from linkd.batch import LinkageBatch
from linkd.errors import InputError
from linkd.graph import ADJ, FEATURES, MAX_NODES, TYPE, VALID, XY
from linkd.model import LinkD, load_checkpoint
from linkd.model.frame import principal_turn, turned
from linkd.validator import N_ANGLES, Validation, check_new_node, validate

STRATEGIES = ("oneshot", "graph", "node")
CHUNK = 1024  # samples grown at once: bounds the memory of the joint paths kept for checks
MOVES = 1e-6  # an end effector whose path spreads less than this (graph units) stands still


@dataclass
class Samples:
    graphs: np.ndarray  # (C*S, 20, 24) float32 decoded graph matrices
    curve_index: np.ndarray  # (C*S,) which conditioning curve each sample belongs to
    valid: np.ndarray  # (C*S,) bool, full validation passed


def load_model(path: str | Path | None = None, device: str = "cpu") -> LinkD:
    """A trained LinkD in eval mode; by default the checkpoint shipped in `linkd.assets`."""
    if path is None:
        with importlib.resources.as_file(
            importlib.resources.files("linkd.assets") / "linkd.pt"
        ) as shipped:
            return load_model(shipped, device)
    if Path(path).is_dir():
        raise InputError(f"{path}: is a folder, not a checkpoint")
    if not Path(path).is_file():
        raise InputError(f"{path}: no such checkpoint")
    try:
        return load_checkpoint(path, device)[0]
    except (pickle.UnpicklingError, RuntimeError, EOFError, KeyError, TypeError) as exc:
        kind = type(exc).__name__
        raise InputError(f"{path}: not a linkd checkpoint (torch.load: {kind})") from None


def empty_graphs(count: int, device: str | torch.device = "cpu") -> torch.Tensor:
    """(count, 20, 24) graph matrices of padding rows only."""
    graphs = torch.full((count, MAX_NODES, FEATURES), -1.0, device=device)
    graphs[..., VALID] = 0
    graphs[..., XY] = 0
    return graphs


def check_graphs(graphs: np.ndarray) -> tuple[np.ndarray, Validation, LinkageBatch]:
    """Full validation of decoded graphs: a valid linkage whose end effector moves."""
    batch = LinkageBatch.from_graphs(graphs)
    result = validate(batch, keep_motion=True)
    paths = result.end_effector_paths(batch)
    return result.valid & (spread(paths) > MOVES), result, batch


def spread(paths):
    """(...) RMS distance of each path (..., T, 2) from its mean, numpy or torch: 0 for a joint
    that never moves."""
    return ((paths - paths.mean(-2, keepdims=True)) ** 2).sum(-1).mean(-1) ** 0.5


def _check_node(rows: torch.Tensor, t: int, paths: torch.Tensor, fixed: torch.Tensor):
    """Is node t acceptable after the prefix? Returns ok, the node's path and a score that
    ranks failed proposals (right topology first, then by transmission margin).

    A stop row is acceptable once the graph has three joints and its last joint moves; a
    joint in the last row of the matrix is the end effector, so it must move too.
    """
    node_fixed = rows[:, TYPE] > 0.5
    links = rows[:, ADJ][:, :t] > 0.5
    ok, path, margin = check_new_node(paths, fixed, node_fixed, rows[:, XY], links)
    if t == MAX_NODES - 1:
        ok = ok & (spread(path) > MOVES)
    right_links = torch.where(node_fixed, (links & ~fixed).sum(1) == 0, links.sum(1) == min(t, 2))
    score = 4.0 * ok + 2.0 * right_links + margin.clamp(-1, 1)
    stop_ok = spread(paths[:, -1]) > MOVES if t >= 3 else torch.zeros_like(ok)
    growing = rows[:, VALID] > 0.5
    ok = torch.where(growing, ok, stop_ok)
    score = torch.where(growing, score, torch.where(stop_ok, 4.0, -3.0))
    return ok, path, score


def _rounds(retries: int) -> list[int]:
    """Retries drawn in rounds of 2, 4, 8, ... proposals at once (fewer, larger batches)."""
    widths, width = [], 2
    while sum(widths) < retries:
        widths.append(min(width, retries - sum(widths)))
        width *= 2
    return widths


def _propose(model, context, t, paths, fixed, retries, steps, generator, null, w):
    """Rows for node t of every growing sample and whether each is acceptable; failing ones are
    resampled, up to `retries` proposals each, drawn in rounds, keeping the best-scoring
    proposal."""
    index = torch.full((len(context),), t, dtype=torch.long, device=context.device)
    rows = model.denoise(context, index, steps, generator, null, w)
    ok, path, score = _check_node(rows, t, paths, fixed)
    for width in _rounds(retries):
        bad = torch.nonzero(~ok)[:, 0]
        if len(bad) == 0:
            break
        many = bad.repeat_interleave(width)
        again = model.denoise(context[many], index[many], steps, generator,
                              None if null is None else null[many], w)  # fmt: skip
        ok2, path2, score2 = _check_node(again, t, paths[many], fixed[many])
        best = score2.view(len(bad), width).argmax(1)
        best += torch.arange(len(bad), device=best.device) * width
        better = score2[best] > score[bad]
        pick, best = bad[better], best[better]
        rows[pick], path[pick], score[pick], ok[pick] = (
            again[best],
            path2[best],
            score2[best],
            ok2[best],
        )
    return rows, path, ok


def _end_failed(graphs, live, t, rows, ok, prefix_paths) -> torch.Tensor:
    """The rows for node t, where the graphs whose node t failed every proposal end instead,
    after their last joint that moves (the third or a later one; rows after it in `graphs`
    become stop rows too): every prefix of a valid linkage is one, so they become valid,
    shorter designs. Graphs with no such joint keep their best failing proposal."""
    if t < 3:
        return rows
    index = torch.arange(t, device=rows.device)
    moving = (spread(prefix_paths) > MOVES) & (index >= 2)  # (B, t)
    last = torch.where(moving, index, -1).amax(1)
    end = ~ok & (last >= 2)
    if not end.any():
        return rows
    stop = empty_graphs(1, rows.device)[0, 0]
    b, j = torch.nonzero(end[:, None] & (index > last[:, None]), as_tuple=True)
    graphs[live[b], j] = stop
    rows = rows.clone()
    rows[end] = stop
    return rows


@torch.inference_mode()
def grow(
    model: LinkD,
    cond: torch.Tensor,
    generator: torch.Generator,
    steps: int | None = None,
    retries: int | None = None,
    guidance: float | None = None,
) -> torch.Tensor:
    """Grow (B, 20, 24) graphs from curve encodings (B, 1 + P, dim), node by node.

    retries=None: no checks (one pass); otherwise node-level retry with that many retries.
    guidance: classifier-free guidance scale (default: the model's); above 1 the backbone also
    reads every partial graph without the curve, as a second half of the batch.
    """
    device = cond.device
    w = model.config.guidance if guidance is None else guidance
    guided = w != 1.0
    b = len(cond)
    graphs = empty_graphs(b, device)
    check = retries is not None
    paths = torch.zeros(b, MAX_NODES, N_ANGLES, 2, device=device) if check else None
    live = torch.arange(b, device=device)
    cache = model.new_cache()
    both = torch.cat([cond, model.null_encoding(cond)]) if guided else cond
    out = model.backbone(graphs[:, :0].repeat(2 if guided else 1, 1, 1), both, cache)[:, -1]
    for t in range(MAX_NODES):
        context, null = (out[: len(live)], out[len(live) :]) if guided else (out, None)
        if check:
            fixed = graphs[live, :t, TYPE] > 0.5
            rows, path, ok = _propose(model, context, t, paths[live, :t], fixed, retries, steps,
                                      generator, null, w)  # fmt: skip
            paths[live, t] = path
            rows = _end_failed(graphs, live, t, rows, ok, paths[live, :t])
        else:
            index = torch.full((len(live),), t, dtype=torch.long, device=device)
            rows = model.denoise(context, index, steps, generator, null, w)
        graphs[live, t] = rows
        keep = rows[:, VALID] > 0.5
        live = live[keep]
        if t + 1 == MAX_NODES or len(live) == 0:
            break
        keep_both = torch.cat([keep, keep]) if guided else keep
        for layer in cache:
            for key, value in layer.items():
                layer[key] = (
                    tuple(v[keep_both] for v in value) if key == "mod" else value[keep_both]
                )
        both = both[keep_both]
        new = rows[keep][:, None]
        out = model.backbone(torch.cat([new, new]) if guided else new, both, cache)[:, -1]
    return graphs


def sample(
    model: LinkD,
    curves: np.ndarray,
    per_curve: int,
    strategy: str = "node",
    retries: int = 25,
    seed: int = 0,
    steps: int | None = None,
    progress: bool = False,
    guidance: float | None = None,
) -> Samples:
    """`per_curve` linkages for each normalised curve (C, 200, 2), grown in batches.

    strategy: "oneshot" (one pass), "graph" (regrow invalid graphs, up to `retries` times) or
    "node" (check each new node, resample failing ones up to `retries` times). Retries are
    drawn in rounds of several proposals at once; the first valid regrown graph is kept, and
    the best-scoring proposal of a node (valid first, then by transmission margin).
    """
    if strategy not in STRATEGIES:
        raise InputError(f"unknown strategy {strategy!r} (choose from {', '.join(STRATEGIES)})")
    curves = np.asarray(curves, dtype=np.float32)
    if curves.ndim != 3 or curves.shape[2] != 2:
        raise InputError(f"curves must be (C, points, 2), got {curves.shape}")
    device = next(model.parameters()).device
    generator = torch.Generator(device).manual_seed(seed)
    curves = torch.as_tensor(curves, device=device)
    turn = principal_turn(curves) if model.config.canonical else None
    with torch.inference_mode():
        cond = model.encode(curves if turn is None else curves @ turn.transpose(1, 2))
    cond = cond.repeat_interleave(per_curve, 0)
    curve_index = np.repeat(np.arange(len(curves)), per_curve)
    chunks = range(0, len(cond), CHUNK)
    graphs, valid = [], []
    rounds = len(_rounds(retries)) if strategy == "graph" else 0
    with _progress(progress, len(chunks) * (1 + rounds)) as advance:
        for start in chunks:
            part = cond[start : start + CHUNK]
            node_retries = retries if strategy == "node" else None
            g = grow(model, part, generator, steps, node_retries, guidance).cpu().numpy()
            ok = check_graphs(g)[0]
            advance()
            for width in _rounds(retries) if strategy == "graph" else []:
                bad = np.flatnonzero(~ok)
                if len(bad) == 0:
                    break
                again = part[np.repeat(bad, width)]
                grown = grow(model, again, generator, steps, None, guidance).cpu().numpy()
                good = check_graphs(grown)[0].reshape(len(bad), width)
                # the first valid regrowth of each graph, or its last one if none is valid
                choice = np.where(good.any(1), good.argmax(1), width - 1)
                g[bad] = grown.reshape(len(bad), width, *g.shape[1:])[np.arange(len(bad)), choice]
                ok[bad] = good.any(1)
                advance()
            graphs.append(g)
            valid.append(ok)
    graphs = np.concatenate(graphs).astype(np.float32)
    if turn is not None:  # back from the principal frame into the curve's own
        back = turn.transpose(1, 2).cpu()[torch.as_tensor(curve_index)]  # R^T undoes R
        graphs = turned(torch.as_tensor(graphs), back).numpy()
    return Samples(graphs, curve_index, np.concatenate(valid))


class _progress:
    """A rich progress bar when asked for and stdout is a terminal; otherwise silent."""

    def __init__(self, enabled: bool, total: int) -> None:
        self.bar = None
        if enabled and sys.stdout.isatty():
            from rich.progress import Progress

            self.bar = Progress(transient=True)
            self.task = self.bar.add_task("sampling", total=total)

    def __enter__(self):
        if self.bar is None:
            return lambda: None
        self.bar.start()
        return lambda: self.bar.advance(self.task)

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.stop()
