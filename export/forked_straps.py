"""Straps beside forked parts: for the mechanisms that need both.

In some mechanisms a part passes over pins that no order of the stack can keep off its layer,
where an eccentric strap (`strapped`) would let those pins cross it through a sheave, while
elsewhere a pin carries parts that others pass between, where only a fork (`forked`) cuts it.
Neither alone layers; together they may. The straps are chosen as `strapped` chooses a core of
them: every candidate's crossings freed with no disc (looser than any choice), then the fewest
of them that still pass the forks' screen (`forkset`), each left out in turn, the least freeing
first; then that core with one strap swapped for another. Each set is searched as the forks
are (`forked.fork_search`, no bracket), on the split plates' candidates (`braced`) with each
strap's sheave grown onto its part, as `strapped` grows it, the crank's shaft whole and then
free to be cut (`drive`). No strapped part is forked, nor any part at a strap's joint but the
sheave's own, whose rod or shaft there keys the sheave.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import replace
from itertools import islice

import numpy as np

from . import strapped
from .braced import swept_candidates
from .drive import cut_cleanly
from .forked import drivable, fork_search
from .forkset import fork_sets
from .layers import Layout, NoFlatLayers, Strap, find_conflicts
from .options import Sizes
from .parts import Assembly

MAX_CORES = 4  # sets of straps searched per width
# Swapped sets screened per width: of the nine mechanisms known built this way, three swap, and
# find theirs within 13 (seed 19's no. 69), while screening all 83 took seed 2026's no. 138 half
# a minute a width, for none.
MAX_SWAPS = 24


def forked_straps_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with some parts made straps and some others forked (NoFlatLayers where none of
    the first MAX_CORES sets of straps layers)."""
    union, roles, posts, conflicts = swept_candidates(assembly, paths, sizes)
    plain = find_conflicts(assembly, paths, sizes)
    positions = paths[:, 0]
    options = strapped._candidates(assembly, plain, positions, sizes)
    freed = {s: strapped._inside(assembly, positions, sizes, s) & strapped._near(plain, s)
             for s in options}  # fmt: skip
    index = {role[1]: u for u, role in enumerate(roles) if role[0] == "part"}

    def loose(chosen: list[Strap], every: bool = False, cut: bool = True) -> bool:
        """Whether the forks' screen passes with the straps' crossings freed and no disc, and
        the forks they allow (or, looser, `every` fork), the crank's shaft free to be cut."""
        off = {(k, index[s.part]) for s in chosen for k in freed[s]}
        blocked = [[u for u in near if (k, u) not in off]
                   for k, near in enumerate(conflicts.blocked)]  # fmt: skip
        forks = drivable if every else _allowed(assembly, chosen)
        sets = fork_sets(assembly, union, roles, replace(conflicts, blocked=blocked), forks, {},
                         1, cut)  # fmt: skip
        return next(sets, None) is not None

    if not options or not loose(options, every=True):
        raise NoFlatLayers("no straps beside forked parts free the pins in the way")
    extended = np.concatenate([paths, np.repeat(posts[:, None], paths.shape[1], 1)])
    swept = strapped._Swept(union, extended, sorted({s.joint for s in options}))
    ranked = sorted(options, key=lambda s: -len(freed[s]))
    for chosen in islice(_cores(ranked, loose), MAX_CORES):
        grown = strapped._with_straps(union, conflicts, swept, sizes,
                                      tuple(_in_union(s, index) for s in chosen))  # fmt: skip
        candidates = (union, roles, posts, grown)
        layout = None
        allowed = _allowed(assembly, chosen)
        for cut in (False, True) if loose(chosen, cut=False) else (True,):
            try:
                layout = fork_search(assembly, candidates, len(paths), sizes, allowed,
                                     brackets=False, cut=cut)  # fmt: skip
            except NoFlatLayers:
                continue
            if cut_cleanly(assembly, layout):
                break
            layout = None
        if layout is None:
            continue
        straps = tuple(strapped._passing(assembly, positions, sizes, layout, s) for s in chosen)
        return replace(layout, straps=straps)
    raise NoFlatLayers("no straps tried beside forked parts layer")


def _cores(ranked: list[Strap], loose: Callable[..., bool]) -> Iterator[tuple[Strap, ...]]:
    """The fewest straps that pass the screen with every fork allowed (each left out in turn,
    the least freeing first: more straps free more), then that core and the core with one
    strap swapped for another, each where it passes with the forks it allows (the first
    MAX_SWAPS swapped sets screened); one strap a part."""
    core = list(ranked)
    for strap in reversed(ranked):
        fewer = [s for s in core if s is not strap]
        if loose(fewer, every=True):
            core = fewer
    swapped = [[*core[:k], other, *core[k + 1 :]] for k in range(len(core))
               for other in ranked if other not in core]  # fmt: skip
    one_a_part = (chosen for chosen in [core, *swapped]
                  if len({s.part for s in chosen}) == len(chosen))  # fmt: skip
    for chosen in islice(one_a_part, MAX_SWAPS + 1):
        if loose(chosen):
            yield tuple(chosen)


def _allowed(assembly: Assembly, chosen: list[Strap]) -> Callable[[Assembly, tuple], bool]:
    """The forks the straps leave: none of a strapped part, nor of a part at a strap's joint
    but the sheave's own, whose rod or shaft there keys the sheave (a fork of it carrying the
    joint turns the strapped part on an arm's rod, as any part it carries)."""
    straps = {s.part for s in chosen}
    keyed = [(s.joint, s.sheave_of) for s in chosen]

    def allowed(a: Assembly, fork: tuple[int, int]) -> bool:
        joints = a.parts[fork[0]].joints
        clear = all(j not in joints or fork[0] == b for j, b in keyed)
        return fork[0] not in straps and clear and drivable(a, fork)

    return allowed


def _in_union(strap: Strap, index: dict[int, int]) -> Strap:
    """The strap with its parts as the split plates' candidates number them."""
    return replace(strap, part=index[strap.part], sheave_of=index[strap.sheave_of])
