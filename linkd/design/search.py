"""The search of a `linkd design` run: propose, look up, place and refine candidate designs.

Candidates come from the proposer (LinkD, or the curve-blind generator) and from the atlas of
precomputed mechanisms; each valid one offers its sub-mechanisms, is placed on the target by
its best similarity (or, on an open or timed target, its best sub-arc of crank angles too),
and the best few are refined, in rounds that grow the best so far by a joint; on drawn
loops, the best are refined once more at the end, their paths traced more finely.
The designer's constraints (in the target's normalised frame) prune, pin, rank and bound the
candidates throughout.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from functools import cache, partial
from typing import TYPE_CHECKING

import numpy as np

from linkd.batch import LinkageBatch
from linkd.constraints import Constraints
from linkd.export import buildable as can_build
from linkd.geometry import Similarity
from linkd.validator import validate

from .atlas import DEFAULT_PATH, Atlas
from .atlas import load as load_atlas
from .budget import (
    BUDGET_STEP,
    FIRST_SHARE,
    around_width,
    budget_steps,
    search_width,
)
from .constrained import pin, pin_stroke, pinned, rank, tightened
from .parallel import PARTS, run_parts, split
from .polish import polish
from .propose import (
    SOURCES,
    Candidates,
    Proposer,
    joined,
    merged,
    model_proposer,
    place,
    propose,
    random_proposer,
    source_name,
    sub_mechanisms,
)
from .refine import RefineSettings, refine
from .rounds import around
from .select import diverse_best, to_mechanism, topology_key
from .stages import Stages
from .stroke import Goal, place_stroke
from .stroke_refine import refine_stroke

if TYPE_CHECKING:
    from .pipeline import DesignOptions

N_POINTS = 200  # points of the normalised target the model and the refinement see
FINE_POINTS = 1000  # of a drawn loop's target in the polish: a 200-point one, filtered at half
# its spacing, rounds corners the user's own points keep
ROUND_ITERATIONS = 130  # L-BFGS iterations of a later round's copies in the default budget
ROUND_ORDERED_ITERATIONS = 50  # of which the first, every copy, at the coarse angles
POLISH = 8  # best designs refined again at the end at finer angles, for each 30 s of the budget
POLISH_ANGLES = 1024
POLISH_ITERATIONS = 200
STALL_ROUNDS = 4  # a longer budget's rounds end after this many that gain under STALL_GAIN
STALL_GAIN = 0.005  # (of the best error): the polish then has their time
POLISH_SHARE = 0.1  # of the budget kept from the rounds for the polish (a long budget's rounds
# would run to the deadline and leave it none)


class NoDesign(Exception):
    """No candidate became a valid, verified design."""


def search(goal: Goal, inner: Constraints, o: DesignOptions, proposer: Proposer | None,
           stages: Stages, deadline: float, report: dict) -> Candidates:  # fmt: skip
    """Propose, place and refine (`o`: the DesignOptions; `inner`: the constraints in the
    target's frame); each candidate's `chamfer` is its latest curve error (on an open or timed
    target: its stroke's Chamfer distance, or its timing error). Fills `report`.

    A longer budget first runs the default budget's search (the designs a default run with the
    same seed finds) and then its own wider one, and on a drawn loop polishes the best of both:
    a wide search settles in different basins, and now and then in worse ones, so a longer
    budget could otherwise deliver a worse design than the default."""
    stroke = goal.stroke
    target = goal.loop(N_POINTS) if stroke else goal.points  # what designs are sampled for
    graphs = _proposals(proposer, target, o, stages, report)
    polishing = o.refine and not stroke
    share = POLISH_SHARE if polishing else 0.0  # of the budget kept for the polish
    rounds_end = deadline - share * o.time_budget
    longer = budget_steps(o.time_budget) > 1
    default_search = None
    if o.refine and o.rounds is None and longer:
        # The default run's own deadline: as far before the wide search's as its budget is
        # shorter, less the polish's share of the difference (a stroke has no polish).
        end = rounds_end - (1 - share) * (o.time_budget - BUDGET_STEP)
        short = replace(o, time_budget=BUDGET_STEP)
        default_report: dict = {}
        default_search = _explore(goal, target, inner, short, graphs, stages, end, default_report)
        report["budget_cut_refinement"] = default_report.get("budget_cut_refinement", False)
        report["default_search"] = {"best": float(np.min(default_search[0].chamfer))}
        if polishing:  # as a default run polishes: the design it would deliver is in hand
            _polish_stage(default_search[0], goal, inner, short, deadline, stages, None)
    candidates, placed = _explore(goal, target, inner, o, graphs, stages, rounds_end, report)
    if default_search is not None:
        found, found_placed = default_search
        candidates, placed = merged(found, candidates), np.concatenate([found_placed, placed])
    if goal.closed:  # a closed timed path: its phase is measured again on delivery
        candidates.ranges = None
    report["refined"] = int((candidates.refined & np.isfinite(candidates.chamfer)).sum())
    used = [k for k in range(len(SOURCES)) if (candidates.source == k).any()]
    report["sources"] = {source_name(k, o.proposer): _contribution(candidates, k, placed)
                         for k in used}  # fmt: skip
    if polishing and time.monotonic() < deadline:
        until = deadline if longer else None
        report["polish"] = _polish_stage(candidates, goal, inner, o, deadline, stages, until)
        if report["polish"]["cut"]:
            report["budget_cut_refinement"] = True
    elif polishing:  # no time was left for it
        report["budget_cut_refinement"] = True
    return candidates


def _polish_stage(candidates: Candidates, goal: Goal, inner: Constraints, o: DesignOptions,
                  deadline: float, stages: Stages, until: float | None) -> dict:  # fmt: skip
    """The polish of a drawn loop's best designs as a stage (`polish.polish`): POLISH for each
    30 s of `o`'s budget, against the user's curve read finely."""
    with stages.stage("polish", "refining the best designs at finer crank angles") as note:
        count = POLISH * budget_steps(o.time_budget)
        settings = tightened(o.refine_settings, inner) if inner else o.refine_settings
        finely = replace(settings, angles=POLISH_ANGLES, iterations=POLISH_ITERATIONS,
                         ordered_iterations=0, ordered_weights=(0.0,), keep=count)  # fmt: skip
        fine = goal.points if goal.fine is None else goal.fine
        refine_finely = _refiner(goal, fine, False, finely, inner, deadline)
        done = polish(candidates, count, o.per_topology, refine_finely,
                      _progress(stages, count, finely), until)  # fmt: skip
        done["cut"] = done.pop("iterations", finely.iterations) < finely.iterations
        if done["designs"]:
            note(f"{done['designs']} designs, best Chamfer {done['before']:.4f} to "
                 f"{done['after']:.4f}")  # fmt: skip
    return done


def _proposals(proposer: Proposer | None, target: np.ndarray, o: DesignOptions,
               stages: Stages, report: dict) -> list:  # fmt: skip
    """The proposer's designs for the target (LinkD's unless `o` or `proposer` says other)."""
    with stages.stage("propose", f"sampling {o.candidates} designs") as note:
        report["proposer"] = o.proposer
        if proposer is None and o.proposer == "random":
            proposer = random_proposer()
        elif proposer is None:
            from linkd.sample import load_model

            proposer = model_proposer(load_model(o.model), o.strategy, guidance=o.guidance)
            report["model"], report["guidance"] = o.model or "shipped", o.guidance
        graphs = propose(proposer, target, o.candidates, o.rotations, o.seed)
        note(f"{len(graphs)} designs")
    report["proposed"] = len(graphs)
    return graphs


def _explore(goal: Goal, target: np.ndarray, inner: Constraints, o: DesignOptions,
             graphs: list, stages: Stages, rounds_end: float,
             report: dict) -> tuple[Candidates, np.ndarray]:  # fmt: skip
    """The proposed `graphs` and the atlas's paths placed on the target, the best refined, and
    the rounds that grow them, as wide as `o`'s budget asks and until `rounds_end`: the
    candidates and their errors as placed, before refinement."""
    stroke = goal.stroke
    rounds, atlas_paths, refine_count = search_width(o.time_budget, o.rounds, o.atlas_paths,
                                                     o.refine_count, stroke)  # fmt: skip
    report["rounds"], report["refine_count"] = rounds, refine_count
    around_count = around_width(o.time_budget, o.around)
    batches = [LinkageBatch.from_graphs(graphs)]
    motor = None if stroke else inner.motor_at  # a loop's candidates chosen for it too
    if o.atlas:  # a stroke by its loop: one arc of the paths found may trace it
        with stages.stage("atlas", "looking the shape up in the atlas") as note:
            atlas = _atlas(o.atlas_path)
            if atlas is None:
                note("no atlas (build one with `linkd atlas build`)")
            else:
                batches.append(atlas.query(target, atlas_paths, motor))
                note(f"{len(batches[-1])} paths of {len(atlas):,}")
    with stages.stage("align", "placing designs on the curve") as note:
        report["valid"] = int(validate(batches[0]).valid.sum())
        if o.every_joint:
            batches[0] = sub_mechanisms(batches[0], target, o.placed, inner.max_joints, motor)
        source = np.concatenate([np.full(len(b), k) for k, b in enumerate(batches)])
        batch = joined(batches)
        if inner.max_joints is not None:  # the sub-mechanisms were chosen within it already
            keep = np.flatnonzero(batch.valid.sum(1) <= inner.max_joints)
            batch, source = batch.subset(keep), source[keep]
        if len(batch) == 0:
            candidates = Candidates(batch, np.zeros(0))
        else:
            candidates = _placed(batch, source, goal, target, inner)
        report["placed"] = len(candidates)  # valid designs and sub-mechanisms, on the curve
        best = f", best Chamfer {candidates.chamfer[0]:.4f}" if len(candidates) else ""
        note(f"{report['valid']} valid, {len(candidates)} placed{best}")
    if len(candidates) == 0 and inner.max_joints is not None:
        raise NoDesign(f"no design has at most {inner.max_joints} joints: none of the "
                       f"{len(graphs)} sampled designs offers a valid one that small")  # fmt: skip
    if len(candidates) == 0:
        raise NoDesign(f"none of the {len(graphs)} sampled designs is a valid mechanism")
    placed = candidates.chamfer.copy()
    candidates.chamfer = candidates.chamfer.copy()
    settings = tightened(o.refine_settings, inner) if inner else o.refine_settings
    if o.refine:
        first_end = rounds_end  # where later rounds follow, they keep a share of the time
        if rounds > 1:
            now = time.monotonic()
            first_end = now + FIRST_SHARE * (rounds_end - now)
        refine_rows = _refiner(goal, target, stroke, settings, inner, first_end)
        with stages.stage("refine", "refining the best designs") as note:
            rows = np.array(diverse_best(candidates.batch, np.arange(len(candidates)),
                                         refine_count, o.per_topology), int)  # fmt: skip
            iterations = refine_rows(candidates, rows, _progress(stages, len(rows), settings))
            report["refine_iterations"] = iterations
            cut = report.get("budget_cut_refinement", False)  # a default search's before
            report["budget_cut_refinement"] = cut or iterations < settings.iterations
            note(f"{len(rows)} designs, {iterations} iterations, "
                 f"best Chamfer {np.min(candidates.chamfer):.4f}")  # fmt: skip
        # Copies of refined designs start near a good fit: one variant, the lighter ordered term,
        # and within the default budget fewer iterations (a longer one runs them all).
        nearby_settings = replace(settings, ordered_weights=settings.ordered_weights[:1])
        if budget_steps(o.time_budget) == 1:
            nearby_settings = replace(nearby_settings,
                                      iterations=min(settings.iterations, ROUND_ITERATIONS),
                                      ordered_iterations=min(settings.ordered_iterations,
                                                             ROUND_ORDERED_ITERATIONS))  # fmt: skip
        refine_nearby = _refiner(goal, target, stroke, nearby_settings, inner, rounds_end)
        buildable = _buildable()
        best, stalled = np.min(candidates.chamfer), 0
        report["rounds_run"] = 1
        for _ in range(rounds - 1):
            if stalled == STALL_ROUNDS:
                break
            if time.monotonic() > rounds_end:  # the rounds left were the time budget's to cut
                report["budget_cut_refinement"] = True
                break
            report["rounds_run"] += 1
            with stages.stage("round", "growing the best designs by a joint") as note:
                nearby = around(candidates, around_count, o.around_copies, o.around_spread,
                                o.seed + len(candidates), buildable, inner.max_joints)  # fmt: skip
                if len(nearby) == 0:
                    note("no design that can be built to search around")
                    break
                found = _placed(nearby, np.full(len(nearby), SOURCES.index("round 2")), goal,
                                target, inner)  # fmt: skip
                first = len(candidates)
                candidates = merged(candidates, found)
                placed = np.concatenate([placed, found.chamfer])
                rows = first + np.array(diverse_best(found.batch, np.arange(len(found)),
                                                     refine_count, refine_count), int)  # fmt: skip
                progress = _progress(stages, len(rows), nearby_settings)
                done = refine_nearby(candidates, rows, progress)
                if done < nearby_settings.iterations:
                    report["budget_cut_refinement"] = True
                note(f"{len(rows)} designs, {done} iterations, "
                     f"best Chamfer {np.min(candidates.chamfer):.4f}")  # fmt: skip
            if budget_steps(o.time_budget) > 1:  # the default's rounds are few: all run
                gained = np.min(candidates.chamfer) < (1 - STALL_GAIN) * best
                best, stalled = min(best, np.min(candidates.chamfer)), 0 if gained else stalled + 1
    return candidates, placed


def _placed(batch: LinkageBatch, source: np.ndarray, goal: Goal, target: np.ndarray,
            inner: Constraints) -> Candidates:  # fmt: skip
    """The valid linkages of `batch` placed on the target (a stroke's by its best sub-arc too),
    pinned where the constraints fix the crank's pivot, and ranked by them."""
    if goal.stroke:
        found = pinned(place_stroke(batch, goal, source), inner, partial(pin_stroke, goal=goal))
    else:
        found = pinned(place(batch, target, source), inner, partial(pin, target=target))
    return rank(found, inner) if inner else found


def _refiner(
    goal: Goal,
    target: np.ndarray,
    stroke: bool,
    settings: RefineSettings,
    inner: Constraints,
    deadline: float,
) -> Callable:
    """A function refining given rows of `candidates` in place (those never within the
    refinement's limits get an infinite error: tried last), in two parts at once (`parallel`),
    each keeping its share of the best variants for the last iterations; it returns the
    iterations run."""
    part_settings = replace(settings, keep=-(-settings.keep // PARTS))

    def refine_rows(candidates: Candidates, rows: np.ndarray, progress) -> int:
        if len(rows) == 0:
            return 0
        parts = split(rows)
        calls = [partial(_refine_part, candidates.batch.subset(part),
                         candidates.ranges[part] if stroke else None, goal, target,
                         part_settings, inner, deadline, progress if k == 0 else None)
                 for k, part in enumerate(parts)]  # fmt: skip
        done = 0
        for part, (result, ranges) in zip(parts, run_parts(calls)):
            ok = result.ok
            if stroke:
                candidates.ranges[part[ok]] = ranges[ok]
            candidates.batch.positions[part[ok]] = result.positions[ok]
            candidates.chamfer[part] = np.where(ok, result.chamfer, np.inf)
            candidates.refined[part] = True
            done = max(done, result.iterations)
        return done

    return refine_rows


def _refine_part(subset, ranges, goal, target, settings, inner, deadline, progress) -> tuple:
    """(RefineResult, refined crank ranges or None) of one part (`_refiner`): a stroke when
    `ranges` are given, else the closed `target`."""
    if ranges is not None:  # of the constraints, only the pinned pivot: its gradient is zero
        pinned = Constraints(motor_at=inner.motor_at) if inner.motor_at is not None else None
        return refine_stroke(subset, ranges, goal, settings, deadline, pinned)
    return refine(subset, target, settings, deadline, constraints=inner or None,
                  progress=progress), None  # fmt: skip


def _buildable() -> Callable[[LinkageBatch, int], bool]:
    """Whether a candidate, as it stands, could be exported with straight links at the usual
    width (layering is the same in any similar frame, so the normalised one serves; the few
    designs that need narrower or bent links are not searched around); remembered per design."""
    known: dict[bytes, bool] = {}

    def buildable(batch: LinkageBatch, row: int) -> bool:
        key = topology_key(batch, row) + batch.positions[row].tobytes()
        if key not in known:
            known[key] = can_build(to_mechanism(batch, row, Similarity(), "mm"), quick=True)
        return known[key]

    return buildable


def _progress(stages: Stages, count: int, settings: RefineSettings) -> Callable:
    def progress(done: int, best: float) -> None:
        stages.progress(f"refining {count} designs: iteration {done} of {settings.iterations}, "
                        f"best Chamfer {best:.4f}")  # fmt: skip

    return progress


@cache
def _atlas(path: str | None) -> Atlas | None:
    """The atlas at `path` (None: the shipped one, or None when it has not been built)."""
    if path is None and not DEFAULT_PATH.exists():
        return None
    return load_atlas(path)


def _contribution(candidates: Candidates, source: int, placed: np.ndarray) -> dict:
    """What one source offered: its candidates placed and refined (within the limits, as
    `refined` counts them), and the best of each (`placed`: the errors before refinement)."""
    mine = candidates.source == source
    refined = candidates.chamfer[mine & candidates.refined]
    return {"placed": int(mine.sum()),
            "best_placed": _finite(np.min(placed[mine], initial=np.inf)),
            "refined": int(np.isfinite(refined).sum()),
            "best_refined": _finite(np.min(refined, initial=np.inf))}  # fmt: skip


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None
