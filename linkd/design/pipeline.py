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

A designer's constraints (`linkd.constraints`, in the user's frame) are honoured from the
start: too many joints never reach alignment, a motor point fixes each placement's translation,
candidates that nearly meet them are refined first, refinement keeps them as barriers (and the
crank pivot pinned), and each design is checked exactly in the user's units before export.

The time budget bounds proposal and refinement (refinement stops when the time left is what
delivery needs); delivery always runs. A run is deterministic for a seed on one machine as long
as the budget does not cut refinement short (report.json says whether it did).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from linkd import __version__
from linkd.batch import LinkageBatch
from linkd.constraints import Constraints, binding, check, describe, no_design
from linkd.curves import read_path
from linkd.outdir import staged_output
from linkd.validator import validate

from .constrained import pin, prune, rank, screen, tightened
from .output import Delivered, deliver, finish, summary
from .propose import (
    Candidates,
    Proposer,
    model_proposer,
    place,
    propose,
    random_proposer,
    sub_mechanisms,
)
from .refine import RefineSettings, refine, single_thread
from .select import diverse_best, to_mechanism, topology_key
from .stages import Stages
from .stroke import Goal, make_goal, place_stroke
from .stroke_refine import refine_stroke

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
    proposer: str = "model"  # "model": LinkD; "random": the generator, blind to the curve
    refine_settings: RefineSettings = field(default_factory=RefineSettings)
    # Designer's constraints, in the curve's frame and units (contract §5).
    constraints: Constraints = field(default_factory=Constraints)
    # open paths and timing (issue 10)
    path: str = "auto"  # "auto", "closed" or "open": what the curve is (see linkd.paths)
    timed: bool = False  # rows equally spaced in time at constant crank speed


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
        points, closed = read_path(curve_path, o.path)
        goal, frame = make_goal(points, closed, o.timed, N_POINTS)
        kind = ("closed" if closed else "open") + (", timed" if o.timed else "")
        note(f"{len(points)} points from {Path(curve_path).name}, {kind} path")
    search: dict = {"strategy": o.strategy, "seed": o.seed, "candidates": o.candidates}
    if o.constraints:
        search["constraints"] = o.constraints.to_dict()
    source = {"tool": f"linkd {__version__}", "command": "design", "curve": Path(curve_path).name,
              "seed": o.seed, "strategy": o.strategy}  # fmt: skip
    try:
        with single_thread(), staged_output(out, force) as stage:
            candidates = _search(goal, frame, o, proposer, stages, start, search)
            found, alternatives, measured = _deliver(candidates, frame, points, o, stages, stage,
                                                     source)  # fmt: skip
            report = {
                "format": "linkd-design-report/1",
                "curve": {
                    "file": str(Path(curve_path).resolve()),
                    "points": len(points),
                    "units": o.units,
                    "path": "closed" if closed else "open",
                    "path_option": o.path,
                    "timed": o.timed,
                },
                "design": summary(found),
                **({"constraints": [m.to_dict() for m in measured]} if measured else {}),
                "search": search,
                "alternatives": alternatives,
                "timings": {},
            }
            with stages.stage("write", "writing plots and report") as note:
                report["timings"] = _timings(stages, start)
                finish(found, points, o.formats, report)
                note(f"{out}/")
            found.folder = Path(out)
    except NoDesign as reason:
        stages.say(f"[red]no design[/]: {reason}")
        return Outcome(None, None, {"search": search, "reason": str(reason)}, [])
    report["timings"] = _timings(stages, start)
    return Outcome(Path(out), found, report, alternatives)


def _search(
    goal: Goal,
    frame,
    o: DesignOptions,
    proposer: Proposer | None,
    stages: Stages,
    start: float,
    search: dict,
) -> Candidates:
    """Propose, place and refine; each candidate's `chamfer` is its latest curve error (on an
    open or timed target: its stroke's Chamfer distance, or its timing error)."""
    stroke = not goal.closed or goal.timed
    target = goal.loop(N_POINTS) if stroke else goal.points  # what designs are sampled for
    inner = o.constraints.mapped(frame.inverse())  # in the target's normalised frame
    with stages.stage("propose", f"sampling {o.candidates} designs") as note:
        search["proposer"] = o.proposer
        if proposer is None and o.proposer == "random":
            proposer = random_proposer()
        elif proposer is None:
            from linkd.sample import load_model

            proposer = model_proposer(load_model(o.model), o.strategy)
            search["model"] = o.model or "shipped"
        graphs = propose(proposer, target, o.candidates, o.rotations, o.seed)
        note(f"{len(graphs)} designs")
    with stages.stage("align", "placing designs on the curve") as note:
        batch = LinkageBatch.from_graphs(graphs)
        search["proposed"], search["valid"] = len(graphs), int(validate(batch).valid.sum())
        if o.every_joint:
            batch = sub_mechanisms(batch, target, o.placed, inner.max_joints)
        batch = prune(batch, inner.max_joints)
        if len(batch) == 0:
            candidates = Candidates(batch, np.zeros(0))
        else:
            candidates = place_stroke(batch, goal) if stroke else place(batch, target)
        if inner.motor_at is not None and not stroke:
            candidates = pin(candidates, target, np.array(inner.motor_at))
        if inner:
            candidates = rank(candidates, inner)
        search["placed"] = len(candidates)  # valid designs and sub-mechanisms, on the curve
        best = f", best Chamfer {candidates.chamfer[0]:.4f}" if len(candidates) else ""
        note(f"{search['valid']} valid, {len(candidates)} placed{best}")
    if len(candidates) == 0 and inner.max_joints is not None:
        raise NoDesign(f"no design has at most {inner.max_joints} joints: none of the "
                       f"{len(graphs)} sampled designs offers a valid one that small")  # fmt: skip
    if len(candidates) == 0:
        raise NoDesign(f"none of the {len(graphs)} sampled designs is a valid mechanism")
    score = candidates.chamfer.copy()
    search["refined"] = 0
    if o.refine:
        rows = np.array(diverse_best(candidates.batch, np.arange(len(candidates)),
                                     o.refine_count, o.per_topology))  # fmt: skip
        deadline = start + o.time_budget - DELIVERY_RESERVE
        total = o.refine_settings.iterations
        with stages.stage("refine", f"refining {len(rows)} designs") as note:
            def progress(done: int, best: float) -> None:
                stages.progress(f"refining {len(rows)} designs: iteration {done} of {total}, "
                                f"best Chamfer {best:.4f}")  # fmt: skip

            settings = tightened(o.refine_settings, inner) if inner else o.refine_settings
            subset = candidates.batch.subset(rows)
            if stroke:
                result, ranges = refine_stroke(subset, candidates.ranges[rows], goal, settings,
                                               deadline)  # fmt: skip
                candidates.ranges[rows[result.ok]] = ranges[result.ok]
            else:
                result = refine(subset, target, settings, deadline, constraints=inner or None,
                                progress=progress)  # fmt: skip
            ok = result.ok
            candidates.batch.positions[rows[ok]] = result.positions[ok]
            score[rows[ok]] = result.chamfer[ok]
            score[rows[~ok]] = np.inf  # never within the refinement's limits: tried last
            search["refined"] = int(ok.sum())
            search["refine_iterations"] = result.iterations
            search["budget_cut_refinement"] = result.iterations < o.refine_settings.iterations
            note(f"{result.iterations} iterations, best Chamfer {np.nanmin(score):.4f}")
    candidates.chamfer = score
    if goal.closed:  # a closed timed path: its phase is measured again on delivery
        candidates.ranges = None
    return candidates


def _deliver(
    candidates: Candidates,
    frame,
    points: np.ndarray,
    o: DesignOptions,
    stages: Stages,
    stage: Path,
    source: dict,
) -> tuple[Delivered, list[dict], list]:
    """Verify designs from the best until one passes; then the alternatives, if asked for.
    With constraints, only designs that meet them all, measured exactly in the user's units,
    are exported; the measurements of the one delivered come back too."""
    order = np.argsort(candidates.chamfer, kind="stable")
    batch = candidates.batch
    c = o.constraints
    if c:
        feasible, screened = screen(batch, frame, c)
        if not feasible.any():
            raise NoDesign(binding(screened, c, o.units))
        order = order[feasible[order]]
    with stages.stage("verify", "exporting and verifying in MuJoCo") as note:
        found, tried, measured, unmet = None, 0, [], []
        for row in order[: o.attempts]:
            tried += 1
            mech, measured = _checked(batch, int(row), frame, o, _range(candidates, row))
            if mech is None:  # within the screening's sampling, but not exactly
                unmet.append(next(m for m in measured if not m.holds))
                continue
            found = deliver(mech, points, stage, o.formats, source, o.timed)
            if found:
                break
        if found is None and unmet and len(unmet) == tried:
            raise NoDesign(f"{no_design(unmet[0], o.units)}; in the best, "
                           f"{describe(unmet[0], o.units)}")  # fmt: skip
        if found is None:
            raise NoDesign(f"none of the best {tried} designs passed validation and MuJoCo")
        note(f"{found.mechanism.n_nodes} joints, {found.export.layers} layers, passed "
             f"on try {tried}")  # fmt: skip
        alternatives = []
        if o.top:
            alternatives = _alternatives(candidates, order, int(row), frame, points, o, stage,
                                         source)  # fmt: skip
            note(f"{len(alternatives)} alternatives")
    return found, alternatives, measured


def _checked(batch: LinkageBatch, row: int, frame, o: DesignOptions, crank_range=None) -> tuple:
    """The candidate `row` in the user's frame and units, its crank pivot exactly on the motor
    point if one was given, and each constraint measured on it; no mechanism (None) when one
    of them does not hold."""
    mech = to_mechanism(batch, row, frame, o.units, crank_range)
    c = o.constraints
    if not c:
        return mech, []
    if c.motor_at is not None:  # exactly there, not up to the rounding of the frame change
        positions = mech.positions.copy()
        positions[mech.motor[0]] = c.motor_at
        mech = mech.replace(positions=positions)
    measured = check(mech, c)
    return (mech if all(m.holds for m in measured) else None), measured


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
        mech, measured = _checked(batch, row, frame, o, _range(candidates, row))
        if mech is None:
            continue
        folder = stage / "alternatives" / str(len(listed) + 1)
        folder.mkdir(parents=True, exist_ok=True)
        alt = deliver(mech, points, folder, o.formats, {**source, "alternative": len(listed) + 1},
                      o.timed)  # fmt: skip
        if alt is None:
            continue
        extra = {"constraints": [m.to_dict() for m in measured]} if measured else {}
        finish(alt, points, o.formats, {"design": summary(alt), **extra})
        listed.append({"rank": len(listed) + 1, "folder": f"alternatives/{folder.name}",
                       **summary(alt), **extra})  # fmt: skip
        if len(listed) == o.top:
            break
    for folder in (stage / "alternatives" / str(len(listed) + 1), stage / "alternatives"):
        if folder.exists() and not any(folder.iterdir()):
            folder.rmdir()
    return listed


def _range(candidates: Candidates, row: int) -> tuple[float, float] | None:
    """The crank range of a candidate on an open path (None on a closed one)."""
    if candidates.ranges is None:
        return None
    a, b = candidates.ranges[int(row)]
    return float(a), float(b)


def _timings(stages: Stages, start: float) -> dict:
    timings = {f"{name}_s": round(seconds, 3) for name, seconds in stages.seconds.items()}
    timings["total_s"] = round(time.monotonic() - start, 3)
    return timings
