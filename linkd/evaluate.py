"""The paper's evaluation: validity and Chamfer distance of LinkD's designs per strategy and seed.

For every target curve one design is sampled per strategy and seed. A design succeeds when it
is a valid linkage (topology and motion) whose end effector moves; its curve error is the
Chamfer distance between its end-effector path at 200 crank angles and the target, both
centred on their points' centroid and scaled to unit RMS radius, with no rotation search.

Two yardsticks say what the model takes from the curve: the same protocol applied to linkd's
random generator (`random`: curated mechanisms drawn blind to the curve, one per curve and
seed), and the conditioning gap (the teacher-forced loss with each graph's own curve against
the loss with another graph's curve: zero for a model that ignores its condition).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from linkd.curves import chamfer_batch, curve_moments, normalise, read_curve, resample
from linkd.errors import InputError
from linkd.graph import VALID
from linkd.model import LinkD
from linkd.sample import STRATEGIES, check_graphs, sample

N_POINTS = 200
BASELINE = "random"  # the generator's curve-blind samples, scored like a strategy


@dataclass
class Targets:
    name: str
    conditioning: np.ndarray  # (C, 200, 2) what the model is given: arc-length resampled
    targets: np.ndarray  # (C, T, 2) what designs are compared with: as stored or read
    graphs: torch.Tensor | None = None  # (C, 20, 24) the true mechanisms, in a data set


def point_normalised(curves: np.ndarray) -> np.ndarray:
    """Centroid 0 and RMS radius 1 of the points as given (the benchmark's convention). A path
    that does not move has no radius: NaN, so such a design counts as invalid."""
    centroid, radius = curve_moments(curves, by_arc_length=False)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (curves - centroid[..., None, :]) / radius[..., None, None]


def design_chamfer(graphs: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(N,) Chamfer distance of each design's end-effector path to its target; nan if invalid."""
    valid, result, batch = check_graphs(graphs)
    distance = np.full(len(graphs), np.nan)
    if valid.any():
        paths = point_normalised(result.end_effector_paths(batch)[valid].astype(np.float64))
        target = point_normalised(np.asarray(targets, np.float64)[valid])
        distance[valid] = chamfer_batch(torch.as_tensor(paths), torch.as_tensor(target)).numpy()
    return distance


def node_counts(graphs: np.ndarray) -> np.ndarray:
    return np.cumprod(graphs[:, :, VALID] > 0.5, axis=1).sum(1)


def dataset_targets(root: str | Path, split: str = "test", count: int | None = None) -> Targets:
    """The first `count` curves of a data split, conditioned the way training conditions."""
    from linkd.training_data import TrainData, conditioning

    data = TrainData.load(root, split)
    curves = data.curves[:count]
    return Targets(f"{Path(root).name}-{split}", conditioning(curves).numpy(), curves.numpy(),
                   data.graphs[:count])  # fmt: skip


def folder_targets(folder: str | Path, count: int | None = None) -> Targets:
    """Every curve CSV of a folder (sorted by name): read, resampled by arc length, normalised.
    Designs are compared with the points as read when there are 200 of them."""
    files = sorted(Path(folder).glob("*.csv"))[:count]
    if not files:
        raise InputError(f"{folder}: no curve CSV files")
    given, targets = [], []
    for file in files:
        points = read_curve(file)
        given.append(normalise(resample(points, N_POINTS))[0])
        targets.append(points if len(points) == N_POINTS else given[-1])
    return Targets(Path(folder).name, np.stack(given), np.stack(targets))


def evaluate(
    model: LinkD,
    targets: Targets,
    strategies: tuple[str, ...] = STRATEGIES,
    seeds: tuple[int, ...] = (0, 1, 2),
    retries: int = 25,
    steps: int | None = None,
    progress: bool = False,
) -> dict:
    """Success rate and mean Chamfer distance per strategy and seed, with mean and std.

    `strategies` may include BASELINE: the generator's curve-blind samples, scored the same way.
    """
    results: dict = {"curves": len(targets.targets), "source": targets.name, "strategies": {}}
    for strategy in strategies:
        runs = []
        for seed in seeds:
            start = time.perf_counter()
            if strategy == BASELINE:
                graphs = random_graphs(len(targets.targets), seed)
            else:
                graphs = sample(model, targets.conditioning, 1, strategy, retries, seed, steps,
                                progress).graphs  # fmt: skip
            seconds = time.perf_counter() - start
            distance = design_chamfer(graphs, targets.targets)
            valid = np.isfinite(distance)
            runs.append({
                "seed": seed,
                "success": float(valid.mean()),
                "chamfer": float(np.nanmean(distance)) if valid.any() else None,
                "n_valid": int(valid.sum()),
                "seconds": round(seconds, 2),
                "node_counts": node_counts(graphs).tolist(),
                "valid": valid.tolist(),
            })  # fmt: skip
        results["strategies"][strategy] = {"runs": runs, **_summary(runs)}
    return results


def random_graphs(count: int, seed: int) -> np.ndarray:
    """`count` graph matrices from linkd's random generator (valid, curated, curve-blind)."""
    from linkd.generator import generate

    return generate(count, np.random.default_rng([seed, 0x6C6B64])).graphs


@torch.no_grad()
def conditioning_gap(model: LinkD, graphs: torch.Tensor, curves: torch.Tensor, seed: int = 0,
                     draws: int = 4) -> dict:  # fmt: skip
    """Teacher-forced loss of graphs (B, 20, 24) with their own conditioning curves (B, 200, 2)
    and with the curves rolled by one (another graph's), under the same diffusion noise.

    The gap (shuffled minus own) is what the model takes from the curve.
    """
    was_training = model.training
    model.eval()
    losses = {}
    for name, given in (("own", curves), ("shuffled", curves.roll(1, 0))):
        torch.manual_seed(seed)
        total, parts = model(graphs, given, draws)
        losses[name] = {"loss": float(total), **{k: float(v) for k, v in parts.items()}}
    model.train(was_training)
    gap = {k: losses["shuffled"][k] - losses["own"][k] for k in losses["own"]}
    return {"own": losses["own"], "shuffled": losses["shuffled"], "gap": gap}


def _summary(runs: list[dict]) -> dict:
    success = np.array([r["success"] for r in runs])
    chamfer = np.array([np.nan if r["chamfer"] is None else r["chamfer"] for r in runs])
    ddof = 1 if len(runs) > 1 else 0
    return {
        "success_mean": float(success.mean()),
        "success_std": float(success.std(ddof=ddof)),
        "chamfer_mean": float(np.nanmean(chamfer)) if np.isfinite(chamfer).any() else None,
        "chamfer_std": float(np.nanstd(chamfer, ddof=ddof)) if np.isfinite(chamfer).sum() > 1
        else 0.0,
    }  # fmt: skip


def sampling_speed(model: LinkD, curve: np.ndarray, count: int = 256, seed: int = 0) -> dict:
    """Node-level designs per second for one curve (the design pipeline's use)."""
    start = time.perf_counter()
    samples = sample(model, curve[None], count, "node", seed=seed)
    seconds = time.perf_counter() - start
    return {"samples": count, "seconds": round(seconds, 3),
            "samples_per_second": round(count / seconds, 1),
            "valid": float(samples.valid.mean())}  # fmt: skip


def table(results: dict) -> str:
    """Plain-text table: success rate and mean Chamfer (mean +- std over seeds) per strategy,
    and the conditioning gap when it was measured."""
    seeds = len(next(iter(results["strategies"].values()))["runs"])
    lines = [
        f"{results['source']}: {results['curves']} curves, {seeds} seeds",
        f"{'strategy':<10} {'success %':>16} {'Chamfer':>18} {'valid n':>9}",
    ]
    for name, s in results["strategies"].items():
        n = np.mean([r["n_valid"] for r in s["runs"]])
        chamfer = "-" if s["chamfer_mean"] is None else (
            f"{s['chamfer_mean']:.4f} ± {s['chamfer_std']:.4f}")  # fmt: skip
        success = f"{100 * s['success_mean']:.2f} ± {100 * s['success_std']:.2f}"
        lines.append(f"{name:<10} {success:>16} {chamfer:>18} {n:>9.0f}")
    gap = results.get("conditioning")
    if gap:
        lines.append(
            f"conditioning: teacher-forced loss {gap['own']['loss']:.4f} with the own curve, "
            f"{gap['shuffled']['loss']:.4f} with another (gap {gap['gap']['loss']:.4f}; "
            f"position {gap['gap']['position']:.4f}, links {gap['gap']['links']:.4f})"
        )
    return "\n".join(lines)


def write_report(results: dict, folder: Path, heatmap_rows: int = 30) -> None:
    """results.json, a bar chart like the paper's (success and Chamfer per strategy) and a
    heatmap of design node counts per curve and seed (the one-to-many view)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    (folder / "table.txt").write_text(table(results) + "\n")
    names = list(results["strategies"])
    s = [results["strategies"][n] for n in names]
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6))
    a.bar(names, [100 * x["success_mean"] for x in s], yerr=[100 * x["success_std"] for x in s],
          color="#4c72b0", capsize=4)  # fmt: skip
    a.set_ylabel("success rate (%)")
    a.set_ylim(0, 105)
    chamfer = [x["chamfer_mean"] or 0.0 for x in s]
    b.bar(names, chamfer, yerr=[x["chamfer_std"] for x in s], color="#55a868", capsize=4)
    for k, x in enumerate(s):
        n = np.mean([r["n_valid"] for r in x["runs"]])
        b.text(k, chamfer[k], f"n={n:.0f}", ha="center", va="bottom", fontsize=8)
    b.set_ylabel("mean Chamfer distance")
    fig.suptitle(f"{results['source']} ({results['curves']} curves)")
    fig.tight_layout()
    fig.savefig(folder / "strategies.png", dpi=120)
    plt.close(fig)

    fig, axes = plt.subplots(1, len(names), figsize=(3 * len(names), 6), squeeze=False)
    for ax, name in zip(axes[0], names):
        runs = results["strategies"][name]["runs"]
        counts = np.array([r["node_counts"][:heatmap_rows] for r in runs], float).T
        valid = np.array([r["valid"][:heatmap_rows] for r in runs]).T
        image = ax.imshow(np.where(valid, counts, np.nan), cmap="viridis", vmin=2, vmax=20,
                          aspect="auto")  # fmt: skip
        ax.set_xticks(range(len(runs)), [f"seed {r['seed']}" for r in runs])
        ax.set_title(name)
        ax.set_ylabel("curve")
    fig.colorbar(image, ax=axes[0].tolist(), label="nodes (blank: invalid)")
    fig.savefig(folder / "node_counts.png", dpi=120)
    plt.close(fig)
