"""Ground pivots on rings beside forked parts: for the few mechanisms that need both.

In some mechanisms the parts at a ground pivot sweep over pins on both sides of them (so no
pin, stub or bracket holds the pivot: `ground_rings` puts those parts on rings held by a lug),
while elsewhere a pin carries parts that others pass between in every order (so one part must
be forked: `forked`). Neither alone layers; together they may. The search is the forks'
(`forked.fork_search`: one fork, then the sets of forks `forkset` screens; no bracket,
and never a part on a ring), on the split plates' candidates with the
ringed parts off their pivot's pin, each ring's clearances as `ground_rings` reckons them and
its lug's post a ground pin like a stub. Pivots are ringed one at a time, then two at once;
each choice is first searched with its rings alone (no lugs: a looser problem), and only where
that layers is each ring given its lug, in the directions that layer alone where there are two.
Every choice is tried with the motor's shaft whole, then again with the crank, where it forks
at the motor, free to have its arms there on stubs from both base and cover (`drive` then cuts
it in two), which only a layout whose halves `drive` can turn apart may use. A construction
of its own, tried after it at every width, rings the motor's pivot too (`crank_ring_layers`):
the crank on a ring, driven at its rim as on a turntable (`turntable`), and so not forked.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import combinations, product

import numpy as np

from . import braced
from .drive import cut_cleanly
from .forked import drivable, fork_search
from .forkset import fork_sets
from .ground_rings import LUGS, MAX_RINGED, _lugged, _Ring, _ring, _ringed
from .layers import Conflicts, Layout, NoFlatLayers
from .options import Sizes
from .parts import Assembly
from .turntable import _off_pivot


def forked_rings_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with the parts at one or two ground pivots on rings held by lugs and some other
    parts forked (NoFlatLayers where no choice layers)."""
    return _forked_rings(assembly, paths, sizes, at_motor=False)


def crank_ring_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """`forked_rings_layers` with the motor's pivot ringed, alone or with one other pivot: the
    crank on a ring, driven at its rim (NoFlatLayers where no choice layers)."""
    return _forked_rings(assembly, paths, sizes, at_motor=True)


def _forked_rings(assembly: Assembly, paths: np.ndarray, sizes: Sizes, at_motor: bool) -> Layout:
    """The rings' choices with the motor's pivot among them (`at_motor`) or not, each (where the
    motor's pivot is not ringed) with the motor's shaft whole, then free to be cut."""
    union, roles, posts, conflicts = braced.swept_candidates(assembly, paths, sizes)
    motor = assembly.crank.joint
    grounds = [pin.joint for pin in assembly.pins if 0 in pin.members]
    choices = [ringed for count in range(1, MAX_RINGED + 1)
               for ringed in combinations(grounds, count)
               if (motor in ringed) == at_motor]  # fmt: skip
    cuts = (False,) if at_motor else (False, True)  # a ringed crank is never forked
    tries = [(cut, ringed) for cut in cuts for ringed in choices]
    first = len(posts) + len(paths)  # the lugs' posts are joints from here on
    rings, loose = {}, {}
    for cut, ringed in tries:
        for g in set(ringed) - set(rings):
            rings[g] = _ring(assembly, union, posts, paths, sizes, g)
        chosen = [rings[g] for g in ringed]
        taken = {p for ring in chosen for p in ring.parts}
        searched, off = assembly, union
        for ring in chosen:
            arms = {q for q, role in enumerate(roles)
                    if role[0] == "arm" and role[1] in ring.parts}  # fmt: skip
            searched = _off_pivot(searched, ring.pivot, set(ring.parts))
            off = _off_pivot(off, ring.pivot, set(ring.parts), arms)
        on_rings = _ringed(off, conflicts, chosen)
        problem = _Problem(searched, roles, posts, sizes, len(paths), taken, cut)
        if ringed not in loose:  # the rings alone, no lugs, the crank free to be cut: loosest
            loose[ringed] = replace(problem, cut=True).screened(off, on_rings)
        if not loose[ringed] or not (cut or problem.screened(off, on_rings)):
            continue
        directions = [range(LUGS)]
        if len(chosen) > 1:
            directions = []
            for ring in chosen:
                directions.append([lug for lug in range(LUGS) if problem.search(
                    *_lugged(off, on_rings, [ring], (lug,), first)) is not None])  # fmt: skip
                if not directions[-1]:
                    break  # its lug layers in no direction even alone: no pair of them does
        for lugs in product(*directions):
            layout = problem.search(*_lugged(off, on_rings, chosen, lugs, first))
            if layout is not None:
                return _with_rings(layout, chosen, lugs, roles, off, on_rings, first)
    raise NoFlatLayers("no ground pivots on rings layer beside forked parts")


@dataclass(frozen=True)
class _Problem:
    """The forks' search for one choice of rings: `searched`, the assembly with the ringed
    parts off their pivots' pins, none of which (`taken`) may be forked."""

    searched: Assembly
    roles: list[tuple]
    posts: np.ndarray
    sizes: Sizes
    posts_from: int  # the brackets' posts are joints from here on (none are used)
    taken: set[int]
    cut: bool  # the crank forked at the motor may be cut in two there (`drive`)

    def allowed(self, assembly: Assembly, fork: tuple[int, int]) -> bool:
        return fork[0] not in self.taken and drivable(assembly, fork)

    def screened(self, union: Assembly, conflicts: Conflicts) -> bool:
        """Whether the forks' screen (`forkset`) passes some set of forks: where it passes
        none, no forks layer these candidates."""
        sets = fork_sets(self.searched, union, self.roles, conflicts, self.allowed, {}, 1, self.cut)
        return next(sets, None) is not None

    def search(self, union: Assembly, conflicts: Conflicts) -> Layout | None:
        """The forks' layout on these candidates (None where none layers)."""
        if not self.screened(union, conflicts):
            return None
        try:
            candidates = (union, self.roles, self.posts, conflicts)
            layout = fork_search(self.searched, candidates, self.posts_from, self.sizes,
                                 self.allowed, brackets=False, cut=self.cut)  # fmt: skip
        except ValueError:
            return None
        return layout if cut_cleanly(self.searched, layout) else None


def _with_rings(
    layout: Layout,
    rings: list[_Ring],
    lugs: tuple[int, ...],
    roles: list[tuple],
    off: Assembly,
    on_rings: Conflicts,
    first: int,
) -> Layout:
    """The forks' layout with the rings' turntables. Each lug's post is held as a ground pin's
    stubs are: from the base up to the rings below every part that passes the post, and from
    the cover down to those above them (the search kept every ring on one of those sides)."""
    lugged, conflicts = _lugged(off, on_rings, rings, lugs, first)
    cover = layout.count - 1
    tables = []
    for k, (ring, lug) in enumerate(zip(rings, lugs)):
        pin = next(n for n, p in enumerate(lugged.pins) if p.name == f"lug{k}")
        passing = [layer for u in conflicts.blocked[pin]
                   for layer in _layers_of(layout, roles, lugged, u)]  # fmt: skip
        mine = sorted(int(layout.layers[p]) for p in ring.parts)
        low = [layer for layer in mine if not passing or layer < min(passing)]
        high = [layer for layer in mine if layer not in low]
        spans = ([(0, low[-1])] if low else []) + ([(high[0], cover)] if high else [])
        tables += ring.turntables(layout.layers, lug, spans)
    return replace(layout, turntables=tuple(tables))


def _layers_of(layout: Layout, roles: list[tuple], union: Assembly, candidate: int) -> list[int]:
    """The layers a candidate of the search stands for in the built layout: a whole part's, a
    forked link's arms (each a copy of the link), a forked plate's arm between those joints."""
    role = roles[candidate]
    if role[0] == "part" and role[1]:
        arms = layout.arms.get(role[1])
        if arms is None:
            return [int(layout.layers[role[1]])]
        return [arm.layer for arm in arms] if union.parts[candidate].kind == "link" else []
    if role[0] == "arm":
        return [arm.layer for arm in layout.arms.get(role[1], ()) if arm.joints == role[2]]
    return []
