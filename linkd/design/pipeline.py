"""The `linkd design` run: a user's curve to a verified, exported mechanism that traces it.

Stages, each timed and shown on a terminal:
1. read     the curve file; resample it by arc length, filtered (drawn.py), and normalise it
            (centroid 0, RMS radius 1), remembering the similarity back to the user's frame;
2. propose  LinkD designs for the target and its turned and mirrored copies, and the
            mechanisms of the atlas whose paths have the target's shape (atlas.py);
3. align    offer each valid design's sub-mechanisms too (any moving joint as end effector,
            with the joints it hangs on), keep those whose shape is most like the target, place
            each on the target by its best similarity, rank by Chamfer;
4. refine   move the joints of the best few (one or two per topology) by batched L-BFGS
            through the differentiable kinematics;
5. verify   of the best few, measured as delivered, the simplest of those alike first, then
            the rest: map each design to the user's frame and units, validate, export and
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
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from linkd import __version__
from linkd.batch import LinkageBatch
from linkd.constraints import Constraints, binding, check, describe, no_design
from linkd.curves import normalise, read_path
from linkd.export import buildable
from linkd.outdir import staged_output
from linkd.scale import check_curve_size

from .constrained import screen
from .drawn import read_target
from .output import (
    Delivered,
    PassedOver,
    deliver,
    finish,
    keep_passed_over,
    skip_counts,
    summary,
    write_report,
)
from .propose import SOURCES, Candidates, Proposer, source_name
from .prune import pruned
from .refine import RefineSettings, single_thread
from .search import FINE_POINTS, N_POINTS, NoDesign, search
from .select import measure, to_mechanism, topology_key
from .stages import Stages
from .stroke import Goal, make_goal

DELIVERY_RESERVE = 8.0  # seconds kept for export, verification and plots
FAILURES_PER_TOPOLOGY = 2  # designs of one topology tried before the next topology
QUICK_AFTER = 4  # export refusals after which the next designs are checked quickly first
QUICK_CHECKS = 200  # quick checks (about 20 ms each) before delivery gives up
SIMPLER_POOL = 32  # best-ranked designs measured as delivered, the simplest alike first:
SIMPLER_WITHIN = 0.1  # those this fraction of the best's curve error from it,
SIMPLER_FLOOR = 0.001  # or this close (normalised, 0.1 % of the curve's RMS radius)


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
    refine_count: int | None = None  # candidates refined together, in each round (each in two
    # variants; None: from the budget, 48 for the default)
    per_topology: int = 2  # of which at most this many share a topology
    attempts: int = 24  # designs tried (validated, exported, verified) before giving up
    model: str | None = None  # checkpoint; None: the shipped one
    guidance: float | None = 1.0  # LinkD's guidance scale here (None: the model's own). Unguided:
    # the search gains more from varied samples than from each one's fidelity, at half the cost
    proposer: str = "model"  # "model": LinkD; "random": the generator, blind to the curve
    refine_settings: RefineSettings = field(default_factory=RefineSettings)
    # Designer's constraints, in the curve's frame and units (contract §5).
    constraints: Constraints = field(default_factory=Constraints)
    # open paths and timing (issue 10)
    path: str = "auto"  # "auto", "closed" or "open": what the curve is (see linkd.paths)
    timed: bool = False  # rows equally spaced in time at constant crank speed
    # The atlas (issue 9): paths looked up by shape next to the proposer's designs.
    atlas: bool = True
    atlas_path: str | None = None  # None: the shipped atlas
    atlas_paths: int | None = None  # paths looked up, nearest first (None: from the budget)
    smooth: float = 0.0  # Gaussian filter of the drawn curve, fraction of its length (drawn.py)
    rounds: int | None = None  # refinement rounds, each after the first growing the best so
    # far by a joint (None: from the budget)
    around: int | None = None  # designs (of distinct topologies) searched around in a round
    # (None: 4 for each 30 s of the budget: longer budgets search around more basins)
    around_copies: int = 128  # copies of each, grown by a joint (rounds.py), all placed on the
    # target and only the best refined: placing a copy costs a fraction of refining it
    around_spread: float = 0.1  # joints of copies with no room to grow move by this much


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
        check_curve_size(points, o.units, str(curve_path))  # before any work
        goal, frame = make_goal(points, closed, o.timed, N_POINTS)
        if closed and not o.timed:  # a drawn loop, read as drawn.py says
            target, frame = normalise(read_target(points, N_POINTS, o.smooth))
            fine = frame.inverse().apply(read_target(points, FINE_POINTS, o.smooth))
            goal = Goal(target, True, False, fine)
        kind = ("closed" if closed else "open") + (", timed" if o.timed else "")
        note(f"{len(points)} points from {Path(curve_path).name}, {kind} path")
    report_search: dict = {"strategy": o.strategy, "seed": o.seed, "candidates": o.candidates}
    if o.constraints:
        report_search["constraints"] = o.constraints.to_dict()
    source = {"tool": f"linkd {__version__}", "command": "design", "curve": Path(curve_path).name,
              "seed": o.seed, "strategy": o.strategy}  # fmt: skip
    passed: list[PassedOver] = []  # the better designs passed over, best first
    try:
        with single_thread(), staged_output(out, force, (Path(curve_path),)) as stage:
            inner = o.constraints.mapped(frame.inverse())  # in the target's normalised frame
            deadline = start + o.time_budget - DELIVERY_RESERVE
            candidates = search(goal, inner, o, proposer, stages, deadline, report_search)
            ends = start + o.time_budget
            found, alternatives, measured = _deliver(candidates, frame, points, o, stages, stage,
                                                     source, passed, ends)  # fmt: skip
            report_search["skipped"] = skip_counts(passed)
            if passed:
                report_search["best_passed_over"] = keep_passed_over(passed[0], stage)
            report_search["found_by"] = found.mechanism.extra["source"]["found_by"]
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
                "export": {"sizes": found.export.sizes},  # as `linkd export` reports them
                **({"constraints": [m.to_dict() for m in measured]} if measured else {}),
                "search": report_search,
                "alternatives": alternatives,
                "timings": {},
            }
            with stages.stage("write", "writing plots and report") as note:
                finish(found, points, o.formats)
                note(f"{out}/")
            report["timings"] = _timings(stages, start)
            write_report(found, report)
            found.folder = Path(out)
    except NoDesign as reason:
        report_search["skipped"] = skip_counts(passed)
        stages.say(f"[red]no design[/]: {reason}")
        return Outcome(None, None, {"search": report_search, "reason": str(reason)}, [])
    report["timings"] = _timings(stages, start)
    return Outcome(Path(out), found, report, alternatives)


def _deliver(
    candidates: Candidates,
    frame,
    points: np.ndarray,
    o: DesignOptions,
    stages: Stages,
    stage: Path,
    source: dict,
    passed: list[PassedOver],
    ends: float,
) -> tuple[Delivered, list[dict], list]:
    """Verify designs from the best until one passes, listing in `passed` each better one passed
    over and why (`output.deliver`; those a quick check refused, unmeasured); then the
    alternatives, if asked for. Past the time budget's end (`ends`, a `time.monotonic()` value)
    the export no longer tries the slow bracket construction. With constraints, only designs
    that meet them all, measured exactly in the user's units, are exported; the measurements of
    the one delivered come back too. After QUICK_AFTER export refusals each next design is first
    checked quickly (straight links at the usual width, what most designs that build need) and
    passed over untried if that refuses it: a ranking full of designs that cannot be built flat,
    as long budgets' rounds leave, costs a few seconds, not the attempts, and still delivers.
    After half the attempts, only designs the later rounds did not grow are tried (`_ranked`)."""
    order = np.argsort(candidates.chamfer, kind="stable")
    batch = candidates.batch
    c = o.constraints
    if c:
        feasible, screened = screen(batch, frame, c)
        if not feasible.any():
            raise NoDesign(binding(screened, c, o.units))
        order = order[feasible[order]]
    order = _simplest_first(order, candidates, frame, points, o)
    with stages.stage("verify", "exporting and verifying in MuJoCo") as note:
        found, tried, measured, unmet, failed = None, 0, [], [], {}
        quick, refused = 0, 0  # quick checks, and designs they passed over
        grown = candidates.source == SOURCES.index("round 2")

        def halfway() -> bool:  # half the attempts made, by the count as it stands
            return tried >= o.attempts // 2

        for row in _ranked(order, grown, halfway):
            # Later rounds fill the top of the ranking with near copies of a few designs: a
            # topology that failed twice is not tried again.
            key = topology_key(batch, int(row))
            if failed.get(key, 0) >= FAILURES_PER_TOPOLOGY:
                continue
            candidate = pruned(batch.subset([int(row)]))
            mech, measured = _checked(candidate, frame, o, _range(candidates, row))
            if mech is not None and skip_counts(passed)["unbuildable"] >= QUICK_AFTER:
                if quick == QUICK_CHECKS:
                    break
                quick += 1
                if not buildable(mech, quick=True):  # not a try: the check costs little
                    passed.append(PassedOver("unbuildable"))
                    refused += 1
                    failed[key] = failed.get(key, 0) + 1
                    continue
            tried += 1
            if mech is None:  # within the screening's sampling, but not exactly
                unmet.append(next(m for m in measured if not m.holds))
            else:
                origin = source_name(candidates.source[row], o.proposer)
                found = deliver(mech, points, stage, o.formats, {**source, "found_by": origin},
                                o.timed, passed, time.monotonic() < ends)  # fmt: skip
                if found:
                    break
                failed[key] = failed.get(key, 0) + 1
            if tried == o.attempts:
                break
        if found is None and unmet and len(unmet) == tried:
            raise NoDesign(f"{no_design(unmet[0], o.units)}; in the best, "
                           f"{describe(unmet[0], o.units)}")  # fmt: skip
        if found is None:
            more = f" ({refused} more checked could not be built)" if refused else ""
            raise NoDesign(f"none of the best {tried} designs passed validation and MuJoCo{more}")
        note(f"{found.mechanism.n_nodes} joints, {found.export.layers} layers, passed "
             f"on try {tried}")  # fmt: skip
        alternatives = []
        if o.top:
            alternatives = _alternatives(candidates, order, int(row), frame, points, o, stage,
                                         source)  # fmt: skip
            note(f"{len(alternatives)} alternatives")
    return found, alternatives, measured


def _simplest_first(order: np.ndarray, candidates: Candidates, frame, points, o) -> np.ndarray:
    """`order` (best first) with its first SIMPLER_POOL designs measured against the user's
    curve as delivery measures them (on a timed curve, by the timing error), and those within
    SIMPLER_WITHIN of the best of them (or SIMPLER_FLOOR, a difference no one sees) put first,
    fewest joints (pruned) first, then the rest of the pool by that error: where several trace
    the curve alike, as on a curve a four-bar traces, the one with the fewest parts is
    delivered. The pool also holds the best-ranked design of each joint count ranked near the
    best (twice as near as alike): later rounds fill the top of the ranking with grown copies
    of a few designs, which would crowd out a smaller one that traces the curve as well."""
    chamfer = candidates.chamfer[order]
    bound = max(chamfer[0] * (1 + 2 * SIMPLER_WITHIN), chamfer[0] + 2 * SIMPLER_FLOOR)
    near = np.flatnonzero(chamfer <= bound)  # ranking positions, best first
    _, smallest = np.unique(candidates.batch.valid[order[near]].sum(1), return_index=True)
    picked = np.union1d(np.arange(min(SIMPLER_POOL, len(order))), near[smallest])
    pool = order[picked]
    error, joints = np.empty(len(pool)), np.empty(len(pool), int)
    for k, row in enumerate(map(int, pool)):
        mech = to_mechanism(pruned(candidates.batch.subset([row])), 0, frame, o.units,
                            _range(candidates, row))  # fmt: skip
        measures = measure(mech, points, o.timed)
        error[k] = measures.timing_error if o.timed else measures.chamfer  # what was ranked
        joints[k] = mech.n_nodes
    alike = error <= max(error.min() * (1 + SIMPLER_WITHIN), error.min() + SIMPLER_FLOOR)
    first = np.lexsort((error, np.where(alike, joints, 0), ~alike))
    return np.concatenate([pool[first], np.delete(order, picked)])


def _ranked(order: np.ndarray, grown: np.ndarray, fall_back: Callable[[], bool]) -> Iterator:
    """The rows in `order` until `fall_back()` says so, then those of them not `grown` by the
    later rounds that were not given yet. A long budget's rounds can fill the top of the ranking
    with large designs that MuJoCo cannot prove (loops that open by more than its tolerance);
    the designs they grew from are smaller and mostly pass."""
    given = set()
    for row in order:
        if fall_back():
            break
        given.add(int(row))
        yield int(row)
    yield from (int(row) for row in order[~grown[order]] if int(row) not in given)


def _checked(candidate: LinkageBatch, frame, o: DesignOptions, crank_range=None) -> tuple:
    """A candidate (its one row, pruned of joints its end effector does not need) in
    the user's frame and units, its crank pivot exactly on the motor point if one was given,
    and each constraint measured on it; no mechanism (None) when one of them does not hold."""
    mech = to_mechanism(candidate, 0, frame, o.units, crank_range)
    c = o.constraints
    if not c:
        return mech, []
    measured = check(mech, c)
    if c.motor_at is not None and all(m.holds for m in measured):
        # Exactly there: the pivot is on it up to the rounding of the frame change. One that
        # is not (a design the search could not pin) is not moved: that would be another one.
        positions = mech.positions.copy()
        positions[mech.motor[0]] = c.motor_at
        mech = mech.replace(positions=positions)
        measured = check(mech, c)
    return (mech if all(m.holds for m in measured) else None), measured


def _alternatives(candidates, order, chosen, frame, points, o, stage, source) -> list[dict]:
    """Up to `o.top` verified designs of topologies other than the chosen one (as delivered,
    pruned), best first."""
    batch = candidates.batch
    seen = {topology_key(pruned(batch.subset([chosen])), 0)}
    kept = {}  # row -> the candidate as delivery exports it, pruned
    for row in map(int, order):
        candidate = pruned(batch.subset([row]))
        key = topology_key(candidate, 0)
        if key not in seen:
            seen.add(key)
            kept[row] = candidate
            if len(kept) == o.attempts * o.top:
                break
    listed: list[dict] = []
    for row, candidate in kept.items():
        mech, measured = _checked(candidate, frame, o, _range(candidates, row))
        if mech is None:
            continue
        folder = stage / "alternatives" / str(len(listed) + 1)
        folder.mkdir(parents=True, exist_ok=True)
        alt = deliver(mech, points, folder, o.formats, {**source, "alternative": len(listed) + 1},
                      o.timed)  # fmt: skip
        if alt is None:
            continue
        extra = {"constraints": [m.to_dict() for m in measured]} if measured else {}
        finish(alt, points, o.formats)
        write_report(alt, {"design": summary(alt), **extra})
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
