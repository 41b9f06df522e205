"""`linkd bench design CURVES...`: run the whole design pipeline on many curves and measure it.

Per curve and in total: whether a valid design came out, whether it passed MuJoCo verification,
its curve error (Chamfer distance, 2000 and 200 points on both curves, in the target's
normalised frame, no further alignment: see `select.curve_error`), its joint count and the
seconds the run took (the model is loaded once, before the first curve). Designs are written to
a temporary folder and thrown away.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import numpy as np

from linkd.curves import write_curve
from linkd.errors import InputError

from .pipeline import DesignOptions, design, search_width
from .propose import Proposer


def curve_files(sources: list[str], limit: int | None = None) -> list[Path]:
    """Curve CSV files: the files given, and every *.csv of the folders given (sorted)."""
    files: list[Path] = []
    for source in map(Path, sources):
        if source.is_dir():
            found = sorted(p for p in source.glob("*.csv") if p.name != "index.csv")
            if not found:
                raise InputError(f"{source}: no curve CSV files")
            files += found
        elif source.is_file():
            files.append(source)
        else:
            raise InputError(f"{source}: no such file or folder")
    return files[:limit]


def dataset_curves(root: str, count: int, folder: Path) -> list[Path]:
    """The first `count` curves of a data set's test split, written as CSV files to `folder`."""
    from linkd.dataset import load_split

    curves = load_split(root, "test")["curves"][:count]
    files = []
    for k, curve in enumerate(np.asarray(curves, dtype=np.float64)):
        files.append(folder / f"test-{k:04d}.csv")
        write_curve(files[-1], curve)
    return files


def run_bench(files: list[Path], options: DesignOptions, proposer: Proposer, say=print) -> dict:
    """Design every curve; returns per-curve rows and the totals."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="linkd-bench-") as scratch:
        for k, file in enumerate(files):
            start = time.perf_counter()
            outcome = design(file, Path(scratch) / f"{k}", options, proposer, show=False)
            seconds = time.perf_counter() - start
            rows.append(_row(file, outcome, seconds))
            say(_line(rows[-1]))
    return {"curves": rows, "total": totals(rows)}


def _row(file: Path, outcome, seconds: float) -> dict:
    figures = outcome.report.get("design") or {}
    return {
        "curve": f"{file.parent.name}/{file.stem}",
        "valid": outcome.design is not None,
        "verified": bool(figures.get("verified", False)),
        "chamfer": figures.get("chamfer"),
        "chamfer_200": figures.get("chamfer_200"),
        "nodes": figures.get("nodes"),
        "seconds": seconds,
        "found_by": outcome.report["search"].get("found_by"),
        "sources": outcome.report["search"].get("sources", {}),
    }


def totals(rows: list[dict]) -> dict:
    def stat(key: str, how) -> float | None:
        values = [r[key] for r in rows if r[key] is not None]
        return float(how(values)) if values else None

    return {
        "curves": len(rows),
        "valid_rate": float(np.mean([r["valid"] for r in rows])) if rows else None,
        "verified_rate": float(np.mean([r["verified"] for r in rows])) if rows else None,
        "chamfer_mean": stat("chamfer", np.mean),
        "chamfer_median": stat("chamfer", np.median),
        "chamfer_200_mean": stat("chamfer_200", np.mean),
        "nodes_mean": stat("nodes", np.mean),
        "seconds_mean": stat("seconds", np.mean),
        "seconds_median": stat("seconds", np.median),
        "seconds_max": stat("seconds", np.max),
        "found_by": {name: sum(r["found_by"] == name for r in rows)
                     for name in sorted({r["found_by"] for r in rows if r["found_by"]})},
        "stages": stages(rows),
    }


def stages(rows: list[dict]) -> dict:
    """Mean over the curves of the best error each stage reached (normalised frame, the
    refinement's own measure): placed candidates from the proposer, from the proposer and the
    atlas, then refined, then after the later rounds. A curve without a figure for a stage
    (the source offered nothing) counts with the stage before."""
    columns: dict[str, list[float]] = {}
    for row in rows:
        sources = row.get("sources") or {}
        best = np.inf

        def reached(name: str, value) -> None:
            nonlocal best
            best = min(best, np.inf if value is None else value)
            columns.setdefault(name, []).append(best)

        reached("model, placed", sources.get("model", {}).get("best_placed"))
        reached("+ atlas, placed", sources.get("atlas", {}).get("best_placed"))
        refined = [sources.get(name, {}).get("best_refined") for name in ("model", "atlas")]
        reached("+ refinement", min((v for v in refined if v is not None), default=None))
        reached("+ later rounds", sources.get("round 2", {}).get("best_refined"))
    return {name: float(np.mean(v)) for name, v in columns.items() if np.isfinite(v).all()}


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _line(row: dict) -> str:
    cells = [
        f"{row['curve']:<20}",
        f"valid {'yes' if row['valid'] else 'no':<3}",
        f"verified {'yes' if row['verified'] else 'no':<3}",
        f"chamfer {_fmt(row['chamfer'], '.4f'):>6}",
        f"(200 pts {_fmt(row['chamfer_200'], '.4f'):>6})",
        f"joints {_fmt(row['nodes'], 'd'):>2}",
        f"{row['seconds']:6.1f} s",
        f"from {row['found_by'] or '-'}",
    ]
    return "  ".join(cells)


def summary_table(total: dict) -> str:
    t = total
    lines = [
        ("curves", str(t["curves"])),
        ("valid", _fmt(t["valid_rate"], ".1%")),
        ("verified", _fmt(t["verified_rate"], ".1%")),
        ("chamfer (2000)", f"mean {_fmt(t['chamfer_mean'], '.4f')}, "
                           f"median {_fmt(t['chamfer_median'], '.4f')}"),
        ("chamfer (200)", f"mean {_fmt(t['chamfer_200_mean'], '.4f')}"),
        ("joints", f"mean {_fmt(t['nodes_mean'], '.1f')}"),
        ("seconds", f"mean {_fmt(t['seconds_mean'], '.1f')}, median "
                    f"{_fmt(t['seconds_median'], '.1f')}, max {_fmt(t['seconds_max'], '.1f')}"),
        ("found by", ", ".join(f"{k} {v}" for k, v in t["found_by"].items()) or "-"),
        ("stages", ", ".join(f"{k} {v:.4f}" for k, v in t["stages"].items()) or "-"),
    ]  # fmt: skip
    return "\n".join(f"{name:<16}{value}" for name, value in lines)


def write_json(path: str | Path, results: dict, options: DesignOptions) -> None:
    from linkd.outdir import write_atomic

    settings = {"candidates": options.candidates, "strategy": options.strategy,
                "seed": options.seed, "time_budget": options.time_budget,
                "refine": options.refine, "atlas": options.atlas and
                (options.atlas_path or "shipped"), "rounds": search_width(options)[0]}  # fmt: skip
    write_atomic(path, json.dumps({"options": settings, **results}, indent=2) + "\n")


def main(args) -> int:
    """`linkd bench design`: parsed arguments in, figures printed (and written as JSON)."""
    from linkd.commands.design import search_options
    from linkd.sample import load_model

    from .propose import model_proposer

    options = DesignOptions(candidates=args.candidates, strategy=args.strategy, seed=args.seed,
                            time_budget=args.time_budget, refine=args.refine,
                            **search_options(args))  # fmt: skip
    proposer = model_proposer(load_model(args.model), args.strategy)
    with tempfile.TemporaryDirectory(prefix="linkd-curves-") as folder:
        files = curve_files(args.curves) if args.curves else []
        if args.dataset:
            files += dataset_curves(args.dataset, args.limit or 100, Path(folder))
        if not files:
            raise InputError("bench design: give curve files or folders, or --dataset")
        results = run_bench(files[: args.limit], options, proposer)
    print(summary_table(results["total"]))
    if args.json:
        write_json(args.json, results, options)
    return 0
