"""`linkd bench design CURVES...`: run the whole design pipeline on many curves and measure it.

Per curve and in total: whether a valid design came out, whether it passed MuJoCo verification,
its curve error (Chamfer distance, 2000 and 200 points on both curves, in the target's
normalised frame, no further alignment: see `select.curve_error`), its joint count and the
seconds the run took (the model is loaded once, before the first curve). Designs are written to
a temporary folder and thrown away.

`--setup user` first places each curve in a user's frame (USER_SCALE mm per unit, moved by
USER_OFFSET); `--setup constrained` also gives it a designer's constraints built around it
(`constraint_setup`), and checks each delivered design against them again; `--setup
no-motor` gives the same constraints but the motor point (an ablation: what pinning costs).
Open paths (from the `closed` column of an index.csv beside the curves, or `--path`) are
measured on the working stroke: its Chamfer distance to the target, and its worst deviation
from the target polyline as a fraction of the target's length. With `--timed` the timing error
is reported too.
"""

from __future__ import annotations

import csv
import json
import tempfile
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from linkd.constraints import Box, Constraints, check
from linkd.curves import read_curve, read_path, resample, write_curve
from linkd.errors import InputError

from .budget import search_width
from .output import SKIP_REASONS
from .pipeline import DesignOptions, design
from .propose import Proposer
from .select import end_effector_path, sampling_floor

USER_SCALE, USER_OFFSET = 100.0, np.array([500.0, 300.0])


def constraint_setup(points: np.ndarray) -> Constraints:
    """Constraints around a curve (M, 2), S the larger side of its bounding box: the motor
    S/4 below its lowest point, under its middle; fixed joints in a box 2 S wide from S/10
    to 3 S/2 below the curve; every joint within an envelope reaching 3 S/2 beyond the curve
    on every side; links at least S/50; at most 10 joints; transmission angles within
    [15, 165] degrees."""
    (x0, y0), (x1, y1) = points.min(0), points.max(0)
    size, middle = max(x1 - x0, y1 - y0), (x0 + x1) / 2
    reach = 1.5 * size
    return Constraints(
        motor_at=(float(middle), float(y0 - size / 4)),
        ground_box=Box(middle - size, y0 - reach, middle + size, y0 - size / 10),
        envelope=Box(x0 - reach, y0 - reach, x1 + reach, y1 + reach),
        min_link=size / 50,
        max_joints=10,
        min_transmission=15.0,
    )


def placed_curve(file: Path, folder: Path) -> Path:
    """The curve of `file` in the user's frame, written to `folder`."""
    placed = folder / file.name
    write_curve(placed, read_curve(file) * USER_SCALE + USER_OFFSET)
    return placed


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


def indexed_kind(file: Path) -> str | None:
    """Open or closed, from the `closed` column of an index.csv in the curve's folder or the
    one above it (rows named like `alphabet/C`), None when there is none."""
    for root in (file.parent, file.parent.parent):
        index = root / "index.csv"
        if not index.is_file():
            continue
        name = file.relative_to(root).with_suffix("").as_posix()
        with index.open(newline="") as handle:
            for row in csv.DictReader(handle):
                if row.get("curve") == name and row.get("closed") in ("0", "1"):
                    return "closed" if row["closed"] == "1" else "open"
    return None


def path_kinds(files: list[Path], path: str) -> list[str]:
    """The --path each curve is designed with: `path` when it is not "auto", else what an
    index.csv says, else "auto"."""
    return [path if path != "auto" else (indexed_kind(f) or "auto") for f in files]


def run_bench(
    files: list[Path],
    options: DesignOptions,
    proposer: Proposer,
    say=print,
    setup: str = "plain",
    kinds: list[str] | None = None,
) -> dict:
    """Design every curve (placed and constrained as `setup` says, each with its --path from
    `kinds`, default the options' own); returns per-curve rows and the totals."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="linkd-bench-") as scratch:
        for k, file in enumerate(files):
            own = replace(options, path=kinds[k]) if kinds else options
            curve, limits = file, Constraints()
            if setup != "plain":
                curve = placed_curve(file, Path(scratch))
            if setup in ("constrained", "no-motor"):
                limits = constraint_setup(read_curve(curve))
                if setup == "no-motor":
                    limits = replace(limits, motor_at=None)
                if k == 0:
                    say(f"constraints for {file.name}: {limits.to_dict()}")
            start = time.perf_counter()
            try:
                outcome = design(curve, Path(scratch) / f"{k}", replace(own, constraints=limits),
                                 proposer, show=False)  # fmt: skip
            except InputError as exc:  # a curve linkd refuses counts as one without a design
                rows.append(_refused_row(file, str(exc), time.perf_counter() - start))
                say(_line(rows[-1]))
                continue
            seconds = time.perf_counter() - start
            rows.append(_row(file, outcome, seconds))
            if limits:
                delivered = outcome.design
                rows[-1]["constraints_hold"] = delivered is not None and all(
                    m.holds for m in check(delivered.mechanism, limits)
                )
                rows[-1]["reason"] = outcome.report.get("reason")
            say(_line(rows[-1]))
    return {"curves": rows, "total": totals(rows)}


def _row(file: Path, outcome, seconds: float) -> dict:
    figures = outcome.report.get("design") or {}
    curve = outcome.report.get("curve") or {}
    row = {
        "curve": f"{file.parent.name}/{file.stem}",
        "path": curve.get("path"),
        "valid": outcome.design is not None,
        "verified": bool(figures.get("verified", False)),
        "chamfer": figures.get("chamfer"),
        "chamfer_200": figures.get("chamfer_200"),
        "nodes": figures.get("nodes"),
        "layers": figures.get("layers"),
        "crank_range_deg": figures.get("crank_range_deg"),
        "deviation": None,
        "floor": None,
        "timing_error": figures.get("timing_error"),
        "seconds": seconds,
        "found_by": outcome.report["search"].get("found_by"),
        "sources": outcome.report["search"].get("sources", {}),
        "polish": outcome.report["search"].get("polish", {}),
        "rounds_run": outcome.report["search"].get("rounds_run"),
        "default_search": outcome.report["search"].get("default_search"),
        "skipped": dict(outcome.report["search"].get("skipped", {})),
        "passed_over": outcome.report["search"].get("best_passed_over", {}).get("chamfer"),
        "timings": dict(outcome.report.get("timings", {})),
    }
    if outcome.design is not None and outcome.design.mechanism.crank_range is not None:
        points, _ = read_path(file, "open")
        row["deviation"] = stroke_deviation(outcome.design.mechanism, points)
    elif curve.get("path") == "closed" and not curve.get("timed"):
        row["floor"] = sampling_floor(read_path(file, "closed")[0])
    return row


def _refused_row(file: Path, reason: str, seconds: float) -> dict:
    keys = ("path", "chamfer", "chamfer_200", "nodes", "layers", "crank_range_deg", "deviation",
            "floor", "timing_error", "found_by", "passed_over")  # fmt: skip
    return {"curve": f"{file.parent.name}/{file.stem}", **dict.fromkeys(keys), "valid": False,
            "verified": False, "seconds": seconds, "sources": {}, "skipped": {},
            "timings": {}, "reason": reason}  # fmt: skip


def stroke_deviation(mech, target: np.ndarray, samples: int = 2000) -> float:
    """Worst distance of a design's working stroke from the open target polyline, and of the
    target from the stroke, as a fraction of the target's length."""
    stroke = end_effector_path(mech, np.linspace(*mech.crank_range, samples))[0]
    length = float(np.linalg.norm(np.diff(target, axis=0), axis=1).sum())
    dense = resample(target, 20 * samples, closed=False)
    away = cKDTree(dense).query(stroke)[0].max()
    missed = cKDTree(resample(stroke, 20 * samples, closed=False)).query(dense)[0].max()
    return float(max(away, missed) / length)


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
        "floor_mean": stat("floor", np.mean),
        "nodes_mean": stat("nodes", np.mean),
        "open": sum(r["path"] == "open" for r in rows),
        "deviation_mean": stat("deviation", np.mean),
        "deviation_max": stat("deviation", np.max),
        "timing_error_mean": stat("timing_error", np.mean),
        "timing_error_median": stat("timing_error", np.median),
        "seconds_mean": stat("seconds", np.mean),
        "seconds_median": stat("seconds", np.median),
        "seconds_max": stat("seconds", np.max),
        "stage_seconds": stage_seconds(rows),
        **_held(rows),
        "skipped": {why: sum(r["skipped"].get(why, 0) for r in rows) for why in SKIP_REASONS},
        "best_skipped": sum(any(r["skipped"].values()) for r in rows),
        "passed_over": [(r["passed_over"], r["chamfer"]) for r in rows if r.get("passed_over")],
        "found_by": dict(sorted(Counter(r["found_by"] for r in rows if r["found_by"]).items())),
        "stages": stages(rows),
    }


def stage_seconds(rows: list[dict]) -> dict:
    """Median seconds of each stage of `linkd design` over the curves that ran it."""
    names = dict.fromkeys(k for r in rows for k in r["timings"] if k != "total_s")
    return {k.removesuffix("_s"): float(np.median([r["timings"][k] for r in rows
                                                   if k in r["timings"]]))
            for k in names}  # fmt: skip


def _held(rows: list[dict]) -> dict:
    """Of the delivered designs, the share that meets every constraint (constrained runs)."""
    checked = [r["constraints_hold"] for r in rows if "constraints_hold" in r and r["valid"]]
    if not any("constraints_hold" in r for r in rows):
        return {}
    return {"constraints_held_rate": float(np.mean(checked)) if checked else None}


def stages(rows: list[dict]) -> dict:
    """Mean over the curves of the best error each stage reached (normalised frame, the
    refinement's own measure): placed candidates from the proposer, from it and the atlas, then
    refined, after the later rounds, and after the polish at finer crank angles. A curve without
    a figure for a stage (the source offered nothing) counts with the stage before."""
    columns: dict[str, list[float]] = {}
    for row in rows:
        sources = row.get("sources") or {}
        best = np.inf

        def reached(name: str, value) -> None:
            nonlocal best
            best = min(best, np.inf if value is None else value)
            columns.setdefault(name, []).append(best)

        proposer = "random" if "random" in sources else "model"
        reached(f"{proposer}, placed", sources.get(proposer, {}).get("best_placed"))
        reached("+ atlas, placed", sources.get("atlas", {}).get("best_placed"))
        refined = [sources.get(name, {}).get("best_refined") for name in (proposer, "atlas")]
        reached("+ refinement", min((v for v in refined if v is not None), default=None))
        reached("+ later rounds", sources.get("round 2", {}).get("best_refined"))
        reached("+ polish", (row.get("polish") or {}).get("after"))
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
    if row.get("reason"):
        cells.append(row["reason"])
    if row["crank_range_deg"] is not None:
        a, b = row["crank_range_deg"]
        cells.append(f"open, crank {a:.0f}..{b:.0f} deg, deviation {row['deviation']:.2%}")
    if row["timing_error"] is not None:
        cells.append(f"timing {row['timing_error']:.4f}")
    return "  ".join(cells)


def summary_table(total: dict) -> str:
    t = total
    lines = [
        ("curves", str(t["curves"])),
        ("valid", _fmt(t["valid_rate"], ".1%")),
        ("verified", _fmt(t["verified_rate"], ".1%")),
        ("chamfer (2000)", f"mean {_fmt(t['chamfer_mean'], '.4f')}, "
                           f"median {_fmt(t['chamfer_median'], '.4f')}; an exact trace of the "
                           f"closed curves: {_fmt(t['floor_mean'], '.4f')}"),
        ("chamfer (200)", f"mean {_fmt(t['chamfer_200_mean'], '.4f')}"),
        ("joints", f"mean {_fmt(t['nodes_mean'], '.1f')}"),
        ("open paths", f"{t['open']}, stroke deviation mean {_fmt(t['deviation_mean'], '.2%')}, "
                       f"max {_fmt(t['deviation_max'], '.2%')} of the path's length"),
        ("timing error", f"mean {_fmt(t['timing_error_mean'], '.4f')}, "
                         f"median {_fmt(t['timing_error_median'], '.4f')}"),
        ("seconds", f"mean {_fmt(t['seconds_mean'], '.1f')}, median "
                    f"{_fmt(t['seconds_median'], '.1f')}, max {_fmt(t['seconds_max'], '.1f')}"),
        ("stage seconds", "median " + (", ".join(f"{k} {v:.1f}"
                                                 for k, v in t["stage_seconds"].items()) or "-")),
        ("skipped", f"{t['best_skipped']} curves' best designs passed over: "
                    + ", ".join(f"{k} {v}" for k, v in t["skipped"].items())
                    + ("; curve error {:.4f} passed over, {:.4f} delivered (means)".format(
                        *np.mean(t["passed_over"], 0)) if t["passed_over"] else "")),
        ("found by", ", ".join(f"{k} {v}" for k, v in t["found_by"].items()) or "-"),
        ("stages", ", ".join(f"{k} {v:.4f}" for k, v in t["stages"].items()) or "-"),
    ]  # fmt: skip
    if "constraints_held_rate" in t:
        lines.append(("constraints", f"{_fmt(t['constraints_held_rate'], '.1%')} of delivered "
                                     "designs meet every one"))  # fmt: skip
    return "\n".join(f"{name:<16}{value}" for name, value in lines)


def _kind(file: Path, kind: str) -> str:
    """Open or closed: as given, or as `linkd.paths` reads the file."""
    return kind if kind != "auto" else ("closed" if read_path(file, "auto")[1] else "open")


def write_json(
    path: str | Path, results: dict, options: DesignOptions, setup: str = "plain"
) -> None:
    from linkd.outdir import write_atomic

    settings = {"candidates": options.candidates, "strategy": options.strategy,
                "seed": options.seed, "time_budget": options.time_budget,
                "refine": options.refine, "proposer": options.proposer,
                "guidance": options.guidance,
                "setup": setup, "path": options.path, "timed": options.timed,
                "atlas": options.atlas and (options.atlas_path or "shipped"),
                "rounds": search_width(options.time_budget, options.rounds,
                                       options.atlas_paths)[0]}  # fmt: skip
    write_atomic(path, json.dumps({"options": settings, **results}, indent=2) + "\n")


def main(args) -> int:
    """`linkd bench design`: parsed arguments in, figures printed (and written as JSON)."""
    from linkd.commands.design import search_options
    from linkd.sample import load_model

    from .propose import model_proposer, random_proposer

    options = DesignOptions(candidates=args.candidates, strategy=args.strategy, seed=args.seed,
                            time_budget=args.time_budget, refine=args.refine,
                            proposer=args.proposer, path=args.path, timed=args.timed,
                            **search_options(args))  # fmt: skip
    if args.guidance is not None:
        options = replace(options, guidance=args.guidance)
    if args.proposer == "random":
        proposer = random_proposer()
    else:
        proposer = model_proposer(load_model(args.model), args.strategy, guidance=options.guidance)
    with tempfile.TemporaryDirectory(prefix="linkd-curves-") as folder:
        files = curve_files(args.curves) if args.curves else []
        if args.dataset:
            files += dataset_curves(args.dataset, args.limit or 100, Path(folder))
        if not files:
            raise InputError("bench design: give curve files or folders, or --dataset")
        kinds = path_kinds(files, args.path)
        if args.only:
            picked = [k for k, f in enumerate(files) if _kind(f, kinds[k]) == args.only]
            files, kinds = [files[k] for k in picked], [kinds[k] for k in picked]
        results = run_bench(files[: args.limit], options, proposer, setup=args.setup,
                            kinds=kinds[: args.limit])  # fmt: skip
    print(summary_table(results["total"]))
    if args.json:
        write_json(args.json, results, options, args.setup)
    return 0
