"""The `linkd design` run: a user's curve to a verified, exported mechanism that traces it.

Stages, each timed and shown on a terminal:
1. read     the curve file; resample it by arc length and normalise it (centroid 0, RMS radius
            1), remembering the similarity back to the user's frame;
2. propose  LinkD designs for the target and its turned and mirrored copies;
3. align    offer each valid design's sub-mechanisms too (any moving joint as end effector,
            with the joints it hangs on), keep those whose shape is most like the target, place
            each on the target by its best similarity, rank by Chamfer;
4. refine   move the joints of the best few (one or two per topology) by batched L-BFGS
            through the differentiable kinematics;
5. verify   from the best, map each design to the user's frame and units, validate, export and
            prove it in MuJoCo until one passes (and as many alternatives as asked for);
6. write    curve.png, animation.html and report.json; the folder appears all at once.

The time budget bounds proposal and refinement (refinement stops when the time left is what
delivery needs); delivery always runs. A run is deterministic for a seed on one machine as long
as the budget does not cut refinement short (report.json says whether it did).
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from linkd import __version__
from linkd.batch import LinkageBatch
from linkd.curves import normalise, read_curve, resample
from linkd.outdir import staged_output

from .output import SKIP_REASONS, Delivered, deliver, finish, summary
from .propose import Candidates, Proposer, model_proposer, place, propose, sub_mechanisms
from .refine import RefineSettings, refine, single_thread
from .select import diverse_best, to_mechanism, topology_key
from .stages import Stages

N_POINTS = 200  # points of the normalised target the model and the refinement see
DELIVERY_RESERVE = 8.0  # seconds kept for export, verification and plots


@dataclass(frozen=True)
class DesignOptions:
    candidates: int = 512  # designs sampled in all
    strategy: str = "node"
    refine: bool = True
    seed: int = 0
    units: str = "mm"
    formats: frozenset[str] = frozenset({"mjcf", "stl"})
    time_budget: float = 30.0  # seconds for the whole run
    top: int = 0  # alternatives with other topologies, under OUT/alternatives/
    rotations: int = 4  # turned copies of the target sampled for, each also mirrored
    every_joint: bool = True  # also offer each sample's sub-mechanisms (any joint as end effector)
    placed: int = 1024  # candidates aligned exactly: the sub-mechanisms most like the target
    refine_count: int = 32  # candidates refined together (each in two variants)
    per_topology: int = 2  # of which at most this many share a topology
    attempts: int = 24  # designs tried (validated, exported, verified) before giving up
    model: str | None = None  # checkpoint; None: the shipped one
    refine_settings: RefineSettings = field(default_factory=RefineSettings)


class NoDesign(Exception):
    """No candidate became a valid, verified design."""


@dataclass
class Outcome:
    out: Path | None  # None when no design was delivered
    design: Delivered | None
    report: dict
    alternatives: list[dict]


def design(
    curve_path: str | Path,
    out: str | Path,
    options: DesignOptions | None = None,
    proposer: Proposer | None = None,
    force: bool = False,
    show: bool | None = None,
) -> Outcome:
    """Design a mechanism for the curve in `curve_path` and write it to the folder `out`.

    proposer: where candidate designs come from (default: LinkD, `options.model`).
    Raises InputError for a bad curve file or output folder (nothing written then).
    """
    o = options or DesignOptions()
    start = time.monotonic()
    stages = Stages(show)
    with stages.stage("read", "reading the curve") as note:
        points = read_curve(curve_path)
        target, frame = normalise(resample(points, N_POINTS))
        note(f"{len(points)} points from {Path(curve_path).name}")
    search: dict = {"strategy": o.strategy, "seed": o.seed, "candidates": o.candidates}
    source = {"tool": f"linkd {__version__}", "command": "design", "curve": Path(curve_path).name,
              "seed": o.seed, "strategy": o.strategy}  # fmt: skip
    try:
        with single_thread(), staged_output(out, force) as stage:
            candidates = _search(target, o, proposer, stages, start, search)
            skipped = Counter(dict.fromkeys(SKIP_REASONS, 0))  # better designs passed over
            search["skipped"] = skipped
            found, alternatives = _deliver(candidates, frame, points, o, stages, stage, source,
                                           skipped)  # fmt: skip
            report = {
                "format": "linkd-design-report/1",
                "curve": {
                    "file": str(Path(curve_path).resolve()),
                    "points": len(points),
                    "units": o.units,
                },
                "design": summary(found),
                "search": search,
                "alternatives": alternatives,
                "timings": {},
            }
            with stages.stage("write", "writing plots and report") as note:
                report["timings"] = _timings(stages, start)
                finish(found, points, o.formats, report)
                note(f"{Path(out).name}/")
            found.folder = Path(out)
    except NoDesign as reason:
        stages.say(f"[red]no design[/]: {reason}")
        return Outcome(None, None, {"search": search, "reason": str(reason)}, [])
    report["timings"] = _timings(stages, start)
    return Outcome(Path(out), found, report, alternatives)


def _search(
    target: np.ndarray,
    o: DesignOptions,
    proposer: Proposer | None,
    stages: Stages,
    start: float,
    search: dict,
) -> Candidates:
    """Propose, place and refine; each candidate's `chamfer` is its latest curve error."""
    with stages.stage("propose", f"sampling {o.candidates} designs") as note:
        if proposer is None:
            from linkd.sample import load_model

            proposer = model_proposer(load_model(o.model), o.strategy)
            search["model"] = o.model or "shipped"
        graphs = propose(proposer, target, o.candidates, o.rotations, o.seed)
        note(f"{len(graphs)} designs")
    with stages.stage("align", "placing designs on the curve") as note:
        batch = LinkageBatch.from_graphs(graphs)
        if o.every_joint:
            batch = sub_mechanisms(batch, target, o.placed)
        candidates = place(batch, target)
        search["proposed"], search["valid"] = len(graphs), len(candidates)
        best = f", best Chamfer {candidates.chamfer[0]:.4f}" if len(candidates) else ""
        note(f"{len(candidates)} valid{best}")
    if len(candidates) == 0:
        raise NoDesign(f"none of the {len(graphs)} sampled designs is a valid mechanism")
    score = candidates.chamfer.copy()
    search["refined"] = 0
    if o.refine:
        rows = np.array(diverse_best(candidates.batch, np.arange(len(candidates)),
                                     o.refine_count, o.per_topology))  # fmt: skip
        deadline = start + o.time_budget - DELIVERY_RESERVE
        with stages.stage("refine", f"refining {len(rows)} designs") as note:
            result = refine(candidates.batch.subset(rows), target, o.refine_settings, deadline)
            ok = result.ok
            candidates.batch.positions[rows[ok]] = result.positions[ok]
            score[rows[ok]] = result.chamfer[ok]
            score[rows[~ok]] = np.inf  # never within the refinement's limits: tried last
            search["refined"] = int(ok.sum())
            search["refine_iterations"] = result.iterations
            search["budget_cut_refinement"] = result.iterations < o.refine_settings.iterations
            note(f"{result.iterations} iterations, best Chamfer {np.nanmin(score):.4f}")
    candidates.chamfer = score
    return candidates


def _deliver(
    candidates: Candidates,
    frame,
    points: np.ndarray,
    o: DesignOptions,
    stages: Stages,
    stage: Path,
    source: dict,
    skipped: Counter,
) -> tuple[Delivered, list[dict]]:
    """Verify designs from the best until one passes, counting in `skipped` why each better one
    was passed over; then the alternatives, if asked for."""
    order = np.argsort(candidates.chamfer, kind="stable")
    batch = candidates.batch
    with stages.stage("verify", "exporting and verifying in MuJoCo") as note:
        found, tried = None, 0
        for row in order[: o.attempts]:
            tried += 1
            mech = to_mechanism(batch, int(row), frame, o.units)
            found = deliver(mech, points, stage, o.formats, source, skipped)
            if found:
                break
        if found is None:
            raise NoDesign(f"none of the best {tried} designs passed validation and MuJoCo")
        note(f"{found.mechanism.n_nodes} joints, {found.export.layers} layers, passed "
             f"on try {tried}")  # fmt: skip
        alternatives = []
        if o.top:
            alternatives = _alternatives(candidates, order, int(row), frame, points, o, stage,
                                         source)  # fmt: skip
            note(f"{len(alternatives)} alternatives")
    return found, alternatives


def _alternatives(candidates, order, chosen, frame, points, o, stage, source) -> list[dict]:
    """Up to `o.top` verified designs of topologies other than the chosen one, best first."""
    batch = candidates.batch
    seen = {topology_key(batch, chosen)}
    rows = []
    for row in order:
        key = topology_key(batch, int(row))
        if key not in seen:
            seen.add(key)
            rows.append(int(row))
    listed: list[dict] = []
    for row in rows[: o.attempts * o.top]:
        folder = stage / "alternatives" / str(len(listed) + 1)
        folder.mkdir(parents=True, exist_ok=True)
        mech = to_mechanism(batch, row, frame, o.units)
        alt = deliver(mech, points, folder, o.formats, {**source, "alternative": len(listed) + 1})
        if alt is None:
            continue
        finish(alt, points, o.formats, {"design": summary(alt)})
        listed.append({"rank": len(listed) + 1, "folder": f"alternatives/{folder.name}",
                       **summary(alt)})  # fmt: skip
        if len(listed) == o.top:
            break
    for folder in (stage / "alternatives" / str(len(listed) + 1), stage / "alternatives"):
        if folder.exists() and not any(folder.iterdir()):
            folder.rmdir()
    return listed


def _timings(stages: Stages, start: float) -> dict:
    timings = {f"{name}_s": round(seconds, 3) for name, seconds in stages.seconds.items()}
    timings["total_s"] = round(time.monotonic() - start, 3)
    return timings
