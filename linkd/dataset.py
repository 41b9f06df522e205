"""The training data on disk: shards of random curated mechanisms, a manifest, fixed splits.

A data set folder holds `manifest.json` and `shard-00000.npz`, `shard-00001.npz`, ... Shard k
holds the samples with global indices k * shard_size onwards and is generated from the seed
(seed, k) alone, so the data does not depend on how many processes made it. Shards are written
atomically, so an interrupted job resumes by making only the missing ones. Each sample belongs to
the train, val or test split by a hash of (seed, global index): fixed, disjoint, no bookkeeping.

Shard arrays (K samples; the same keys `load_split` returns):
    graphs   (K, 20, 24) float32  graph matrices (linkd.graph layout, positions in [-1, 1])
    curves   (K, 200, 2) float32  end-effector path at crank angles 2*pi*k/200, centroid 0,
                                  RMS radius 1; in the graph's frame: centre + scale * curve
    centre   (K, 2) float32, scale (K,) float32
    n_nodes  (K,) int8            joint count (5..20); the end effector is the last joint
    margin   (K,) float32         min sin^2 of any transmission angle over the cycle
    index    (K,) int64           global sample index
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from linkd.errors import InputError
from linkd.generator import GeneratorSettings, Samples, generate

FORMAT = "linkd-dataset/1"
MANIFEST = "manifest.json"
SHARD_SIZE = 10_000
SPLITS = {"train": 0.98, "val": 0.01, "test": 0.01}
SPLIT_RULE = "splitmix64(seed * 2^32 + index) / 2^64 against the cumulative fractions"


def shard_name(k: int) -> str:
    return f"shard-{k:05d}.npz"


def shard_counts(count: int, shard_size: int) -> list[int]:
    """Samples in each shard: full shards and a last partial one."""
    full, rest = divmod(count, shard_size)
    return [shard_size] * full + ([rest] if rest else [])


def generate_shard(k: int, count: int, seed: int, settings: GeneratorSettings) -> Samples:
    """Shard k's samples: a function of (seed, k, count, settings) only."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, k]))
    return generate(count, rng, settings)


def split_of(index: np.ndarray, seed: int) -> np.ndarray:
    """(K,) split name of each global sample index: a fixed hash, uniform in [0, 1)."""
    z = np.asarray(index, np.uint64) + np.uint64(seed % 2**32) * np.uint64(2**32)
    with np.errstate(over="ignore"):
        z = z + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    u = (z >> np.uint64(11)).astype(np.float64) / 2.0**53
    edges = np.cumsum(list(SPLITS.values()))
    names = np.array(list(SPLITS))
    return names[np.minimum(np.searchsorted(edges, u, side="right"), len(names) - 1)]


def _arrays(samples: Samples, first: int) -> dict[str, np.ndarray]:
    arrays = {field.name: getattr(samples, field.name) for field in dataclasses.fields(samples)}
    arrays["index"] = np.arange(first, first + len(samples), dtype=np.int64)
    return arrays


def _write_shard(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write through a temporary file, then rename: a shard is either whole or absent."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            np.savez_compressed(handle, **arrays)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _shard_complete(path: Path, count: int) -> bool:
    if not path.is_file():
        return False
    try:
        with np.load(path) as data:
            return len(data["n_nodes"]) == count
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return False


def _make_shard(job: tuple) -> None:
    """Worker: generate and write one shard."""
    root, k, first, count, seed, settings = job
    samples = generate_shard(k, count, seed, settings)
    _write_shard(Path(root) / shard_name(k), _arrays(samples, first))


def _generate_job(job: tuple) -> Samples:
    k, count, seed, settings = job
    return generate_shard(k, count, seed, settings)


def _run(jobs: list, work: Callable, sizes: list[int], workers: int, label: str) -> list:
    """Run jobs over `workers` processes with a progress bar counting samples (`sizes[k]` for
    job k; quiet when not on a terminal). Results come back in job order."""
    from rich import progress
    from rich.console import Console

    console = Console(stderr=True)
    columns = (
        progress.TextColumn("{task.description}"),
        progress.BarColumn(),
        progress.MofNCompleteColumn(),
        progress.TimeElapsedColumn(),
        progress.TimeRemainingColumn(),
    )
    results = [None] * len(jobs)
    quiet = not console.is_terminal
    with progress.Progress(*columns, console=console, disable=quiet) as bar:
        task = bar.add_task(label, total=sum(sizes))
        if workers <= 1 or len(jobs) <= 1:
            for k, job in enumerate(jobs):
                results[k] = work(job)
                bar.advance(task, sizes[k])
            return results
        import multiprocessing

        with multiprocessing.get_context("spawn").Pool(min(workers, len(jobs))) as pool:
            tagged = [(k, work, job) for k, job in enumerate(jobs)]
            for k, result in pool.imap_unordered(_tagged, tagged):
                results[k] = result
                bar.advance(task, sizes[k])
    return results


def _tagged(item: tuple) -> tuple:
    k, work, job = item
    return k, work(job)


def generate_parallel(
    count: int,
    seed: int,
    workers: int,
    settings: GeneratorSettings | None = None,
    shard_size: int = SHARD_SIZE,
) -> Samples:
    """`count` samples in memory, exactly as `build` would store them (same seeds per shard)."""
    settings = settings or GeneratorSettings()
    counts = shard_counts(count, shard_size)
    jobs = [(k, n, seed, settings) for k, n in enumerate(counts)]
    parts = _run(jobs, _generate_job, counts, workers, "generating")
    return Samples.concatenate(parts) if parts else generate(0, seed, settings)


def _manifest(count, seed, shard_size, settings: GeneratorSettings, complete: bool) -> dict:
    return {
        "format": FORMAT,
        "seed": seed,
        "count": count,
        "shard_size": shard_size,
        "complete": complete,
        "shards": [
            {"file": shard_name(k), "first": k * shard_size, "count": n}
            for k, n in enumerate(shard_counts(count, shard_size))
        ],
        "generator": settings.to_dict(),
        "splits": {"fractions": SPLITS, "rule": SPLIT_RULE},
    }


def _write_manifest(root: Path, manifest: dict) -> None:
    from linkd.outdir import write_atomic

    write_atomic(root / MANIFEST, json.dumps(manifest, indent=2) + "\n")


def build(
    root: str | Path,
    count: int,
    seed: int = 0,
    workers: int = 1,
    shard_size: int = SHARD_SIZE,
    settings: GeneratorSettings | None = None,
) -> tuple[dict, int]:
    """Make (or finish) the data set in `root`; returns its manifest and the samples made now.

    An existing folder must hold a data set made with the same seed, shard size and generator
    settings; its complete shards are kept. Raises InputError otherwise.
    """
    root = Path(root)
    settings = settings or GeneratorSettings()
    manifest = _manifest(count, seed, shard_size, settings, complete=False)
    _check_resumable(root, manifest)
    root.mkdir(parents=True, exist_ok=True)
    _write_manifest(root, manifest)
    jobs = [
        (str(root), k, shard["first"], shard["count"], seed, settings)
        for k, shard in enumerate(manifest["shards"])
        if not _shard_complete(root / shard["file"], shard["count"])
    ]
    sizes = [job[3] for job in jobs]
    _run(jobs, _make_shard, sizes, workers, "dataset")
    manifest["complete"] = True
    _write_manifest(root, manifest)
    return manifest, sum(sizes)


def _check_resumable(root: Path, manifest: dict) -> None:
    if not root.exists():
        return
    if not root.is_dir():
        raise InputError(f"{root}: exists and is not a folder")
    path = root / MANIFEST
    if not path.is_file():
        if any(root.iterdir()):
            raise InputError(f"{root}: folder is not empty and holds no {MANIFEST}")
        return
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: unreadable manifest ({exc})") from None
    keys = ("format", "seed", "shard_size", "generator")
    ours = json.loads(json.dumps(manifest))  # as it reads back (tuples become lists)
    changed = [key for key in keys if old.get(key) != ours[key]]
    if changed:
        raise InputError(f"{path}: a data set with another {', '.join(changed)} is there")


def read_manifest(root: str | Path) -> dict:
    """The manifest of a complete data set (InputError if missing, foreign or unfinished)."""
    path = Path(root) / MANIFEST
    try:
        manifest = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the data set manifest ({exc})") from None
    if manifest.get("format") != FORMAT:
        raise InputError(f"{path}: not a {FORMAT} manifest")
    if not manifest.get("complete"):
        raise InputError(f"{path}: the data set is unfinished (run `linkd dataset` again)")
    return manifest


def load_split(root: str | Path, split: str) -> dict[str, np.ndarray]:
    """All samples of one split ("train", "val" or "test") of a data set, as numpy arrays.

    Keys: graphs (K, 20, 24) float32, curves (K, 200, 2) float32, centre (K, 2) float32,
    scale (K,) float32, n_nodes (K,) int64, margin (K,) float32, index (K,) int64.
    """
    if split not in SPLITS:
        raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    manifest = read_manifest(root)
    parts: dict[str, list[np.ndarray]] = {}
    for shard in manifest["shards"]:
        with np.load(Path(root) / shard["file"]) as data:
            keep = split_of(data["index"], manifest["seed"]) == split
            for key in data.files:
                parts.setdefault(key, []).append(data[key][keep])
    arrays = {key: np.concatenate(values) for key, values in parts.items()}
    arrays["n_nodes"] = arrays["n_nodes"].astype(np.int64)
    return arrays
