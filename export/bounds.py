"""How far a refused mechanism is from being built: the loosest problems of the last
constructions, settled exactly (`exact`), so that a refusal is known to be one and not a search
that gave up (`linkd bench export --bounds`).

Each bound leaves out something a real build needs, so it is looser than any build of its kind:
where a bound finds no order of layers, no build of that kind exists. In all of them plates are
whole or cut into stars in every way (`braced`), every ground pin not asked about is held as
stubs from the base or the cover, and the motor's shaft may be cut in two (`drive`). Straps,
bent links and forks are not in them (each frees pins in ways of its own, which the export
searches itself), so a mechanism with no order here may still be built with those.

- held: the smallest sets of ground pivots that would have to be held in some way other than
  by a pin or stubs. They are simply left out of the problem, the fewest first. None at all
  means that even with every ground pin left out no order exists: what keeps the mechanism from
  layering lies among its moving pins.
- brackets: a bracket at each pivot of such a set (up to MAX_BRACKETED of them), in every
  combination of its `braced.DIRECTIONS` directions (the first MAX_BRACKET_TRIES of them).
- rings: the pivots of each such set made ground rings that the parts there turn in, as the crank
  does on a turntable (`turntable`), with no pin at the pivot. Only the pins whose paths come
  near the ring keep off a part's layer, but those inside its hole. Only the parts whose joints
  come near the ring may not share that layer. The ring's bar out to a post is left out; where
  some split layers even so, each ring is given a bar, a bracket's arm on the ring's layer, in
  every combination of directions (the first MAX_BRACKET_TRIES).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace
from itertools import combinations, islice, product

import numpy as np

from linkd.mechanism import Mechanism

from . import braced, turntable
from .layers import Conflicts, NoFlatLayers, largest_step, stack_layers, sweep
from .options import ExportOptions, Sizes, resolve_sizes
from .parts import Assembly, assemble

MAX_BRACKETED = 3  # pivots whose brackets are tried in every combination of directions
MAX_BRACKET_TRIES = 5_000  # of those choices (a split and a direction at each pivot), a set


@dataclass(frozen=True)
class Bounds:
    """Each count is (choices that layer, choices tried[, choices in all])."""

    width: float  # of the usual link width
    held: tuple[tuple[int, ...], ...]  # the smallest sets of ground pivots to hold otherwise
    brackets: dict[tuple[int, ...], tuple[int, int, int]]  # per set of `held` so small
    rings: dict[tuple[int, ...], tuple[tuple[int, int], ...]]  # per set of `held`: the rings,
    # then (where they layer) with a bar each

    def describe(self) -> str:
        """One line: what would have to be held otherwise, and whether brackets or rings can."""
        if not self.held:
            return "none layers even with every ground pin held otherwise"
        if self.held == ((),):
            return "layers with every ground pin as a pin or stubs"
        sets = " or ".join("+".join(map(str, pivots)) for pivots in self.held)
        words = [f"layers only with pivots {sets} held otherwise"]
        if self.brackets:
            words.append("brackets there " + ", ".join(
                f"{'+'.join(map(str, pivots))}: {_counted(*count)}"
                for pivots, count in self.brackets.items()))  # fmt: skip
        rings = [f"{'+'.join(map(str, pivots))}: {_counted(*counts[0])}"
                 + (f", with a bar each {_counted(*counts[1])}" if len(counts) > 1 else "")
                 for pivots, counts in self.rings.items()]  # fmt: skip
        words.append("rings there " + ", ".join(rings))
        return "; ".join(words)


def _counted(ok: int, tried: int, total: int | None = None) -> str:
    return f"{ok} of {tried}" + (f" (the first, of {total})" if total and total > tried else "")


@dataclass(frozen=True)
class _Problem:
    """The candidates a bound searches (`braced.swept_candidates`) at one width."""

    assembly: Assembly
    paths: np.ndarray
    sizes: Sizes
    union: Assembly
    roles: list[tuple]
    conflicts: Conflicts
    ground: tuple[int, ...]

    def splits(self, whole: set[int] = frozenset()) -> Iterator[dict[int, tuple]]:
        """Every way to cut the plates (but those `whole`) into stars, none cut first."""
        parts = self.assembly.parts
        plates = [q for q, part in enumerate(parts) if part.kind == "plate" and q not in whole]
        return braced._splits({q: braced._stars(parts[q]) for q in plates})


def bounds(mech: Mechanism, width: float = 0.25) -> Bounds:
    """The bounds of a mechanism at `width` of the usual link width (the export's narrowest)."""
    problem = _problem(mech, width)
    held = _held(problem)
    brackets = {
        pivots: _bracketed(problem, pivots, splits)
        for pivots, splits in held.items()
        if 0 < len(pivots) <= MAX_BRACKETED
    }
    rings = {pivots: _ringed(problem, pivots) for pivots in held if pivots}
    return Bounds(width, tuple(held), brackets, rings)


def _problem(mech: Mechanism, width: float) -> _Problem:
    assembly = assemble(mech)
    usual = resolve_sizes(mech, assembly.parts, None).link_width
    sizes = resolve_sizes(mech, assembly.parts, ExportOptions(link_width=usual * width))
    paths = sweep(mech, sizes.link_width)
    union, roles, _, conflicts = braced.swept_candidates(assembly, paths, sizes)
    ground = tuple(pin.joint for pin in assembly.pins if 0 in pin.members)
    return _Problem(assembly, paths, sizes, union, roles, conflicts, ground)


def _layers(
    problem: _Problem,
    split: dict[int, tuple],
    union: Assembly | None = None,
    conflicts: Conflicts | None = None,
    brackets: tuple[int, ...] = (),
    dropped: tuple[int, ...] = (),
) -> bool:
    """Whether some order of layers keeps every pin clear: the plates cut as `split`, the
    `brackets` candidates holding their pivots, the pins at the pivots `dropped` left out, every
    other ground pin as stubs, the motor's too (the crank cut in two)."""
    union = problem.union if union is None else union
    conflicts = problem.conflicts if conflicts is None else conflicts
    keep = braced._kept(problem.roles, split, list(brackets))
    free = tuple(problem.roles[q][1] for q in brackets)
    chosen, share = braced._subset(union, conflicts, keep, free, dropped)
    motor = problem.assembly.crank.joint
    shafts = braced._shafts(chosen, [problem.roles[q] for q in keep])
    shafts = [k for k in shafts if chosen.pins[k].joint != motor]
    try:
        stack_layers(chosen, share, problem.sizes, stubs=True, whole=shafts, fewest=False)
    except NoFlatLayers:
        return False
    return True


def _held(problem: _Problem) -> dict[tuple[int, ...], list[dict]]:
    """The smallest sets of ground pivots that, left out, let some split layer, each with the
    splits that do (empty: none, even with them all left out)."""
    for count in range(len(problem.ground) + 1):
        found = {}
        for pivots in combinations(problem.ground, count):
            splits = [s for s in problem.splits() if _layers(problem, s, dropped=pivots)]
            if splits:
                found[pivots] = splits
        if found:
            return found
    return {}


def _bracketed(
    problem: _Problem, pivots: tuple[int, ...], splits: list[dict]
) -> tuple[int, int, int]:
    """A bracket at each of the `pivots` in every combination of directions, with each of the
    `splits` that layer with those pivots left out (no other can): the first MAX_BRACKET_TRIES."""
    choices = [[q for q, role in enumerate(problem.roles) if role[:2] == ("bracket", pivot)]
               for pivot in pivots]  # fmt: skip
    tried = list(islice(((s, c) for s in splits for c in product(*choices)), MAX_BRACKET_TRIES))
    total = len(splits) * int(np.prod([len(c) for c in choices]))
    return sum(_layers(problem, s, brackets=combo) for s, combo in tried), len(tried), total


def _ringed(problem: _Problem, pivots: tuple[int, ...]) -> tuple[tuple[int, int], ...]:
    """Rings at the `pivots` with every split of the other plates; where some split layers, then
    each ring given a bar on its layer, straight out to a post (`braced`'s brackets), in every
    combination of directions: how many layer with one of those splits."""
    union, conflicts, discs = _rings(problem, pivots)
    splits = list(problem.splits(whole={p for parts in discs.values() for p in parts}))
    loose = [s for s in splits if _layers(problem, s, union, conflicts)]
    if not loose:
        return ((0, len(splits)),)
    bars = [[q for q, role in enumerate(problem.roles) if role[:2] == ("bracket", pivot)]
            for pivot in pivots]  # fmt: skip
    combos = list(islice(product(*bars), MAX_BRACKET_TRIES))
    barred = sum(any(_layers(problem, s, union, _barred(problem, conflicts, discs, combo))
                     for s in loose) for combo in combos)  # fmt: skip
    return (len(loose), len(splits)), (barred, len(combos))


def _rings(problem: _Problem, pivots: tuple[int, ...]) -> tuple[Assembly, Conflicts, dict]:
    """The candidates and conflicts with the parts at the `pivots` (`discs`, by pivot) off their
    pins, on rings. A part's disc reaches half a width beyond its farthest joint; the ring, a
    clearance and half a width more."""
    sizes, paths = problem.sizes, problem.paths
    union, near = problem.union, problem.conflicts.parts.copy()
    blocked = [list(parts) for parts in problem.conflicts.blocked]
    reach = sizes.hole_diameter / 2 + sizes.clearance + largest_step(paths)
    discs = {}
    for pivot in pivots:
        pin = next(pin for pin in problem.assembly.pins if pin.joint == pivot)
        discs[pivot] = taken = {m for m in pin.members if m}
        arms = {q for q, role in enumerate(problem.roles) if role[0] == "arm" and role[1] in taken}
        union = turntable._off_pivot(union, pivot, taken, arms)
        away = np.linalg.norm(paths - paths[pivot, :1], axis=-1)  # (N, T) from the pivot
        for p in taken:
            radii = away[[j for j in problem.assembly.parts[p].joints if j != pivot], 0]
            outer = radii.max() + sizes.link_width + sizes.clearance
            inside = turntable._inside(paths, pivot, sizes, turntable._hole(radii.min(), sizes))
            for other, parts in zip(union.pins, blocked):
                free = p in other.members or other.name.startswith("post") or other.joint in inside
                passes = other.joint < len(paths) and away[other.joint].min() < outer + reach
                if passes and not free and p not in parts:
                    parts.append(p)
            for q, part in enumerate(union.parts):
                joints = list(part.joints)  # a bracket's post is no joint of the sweep
                if q in (0, p) or max(joints, default=len(paths)) >= len(paths):
                    continue
                if away[joints].min() < outer + sizes.link_width / 2 + sizes.clearance:
                    near[p, q] = near[q, p] = True
    return union, replace(problem.conflicts, parts=near, blocked=blocked), discs


def _barred(
    problem: _Problem, conflicts: Conflicts, discs: dict, bars: tuple[int, ...]
) -> Conflicts:
    """The rings' conflicts with each ring's bar (a bracket candidate) on its parts' layer: what
    comes near the bar may not share that layer, nor may a pin the bar passes cross it."""
    near = conflicts.parts.copy()
    blocked = [list(parts) for parts in conflicts.blocked]
    for pivot, bar in zip(discs, bars):
        for p in discs[pivot]:
            near[p] |= problem.conflicts.parts[bar]
            near[:, p] |= problem.conflicts.parts[:, bar]
            near[p, p] = False
            for parts, passing in zip(blocked, problem.conflicts.blocked):
                if bar in passing and p not in parts:
                    parts.append(p)
    return replace(conflicts, parts=near, blocked=blocked)
