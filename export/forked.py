"""Forked parts: a part made as one arm per part it carries, so that each can turn on its own
side of the stack.

Where a joint carries several parts, their pin spans every layer between them, and in some
mechanisms no order keeps that span clear: two couplers hung on the crank tip each sweep over
the other's pin, or the parts a crank carries wall in its pivot, which a bracket must hold from
inside the stack. A fork cuts that pin, as a bicycle's crank does: the part is made as one arm
from a shaft joint to a joint it shares, for each part it carries there, all fixed on the
shaft; at that joint each arm has a rod of its own, fixed in the arm, on which its one part
turns. The rods at a joint are coaxial but need not meet in z (where they would, they are one
rod), so other parts may pass between them, and a bracket may hold the shaft between the arms.

One part is forked, at one of its joints, with at most one ground pin on a bracket (the fewest
brackets first, then the parts with the fewest joints); where none layers, several parts are
forked at once, no two sharing a joint, with at most one ground pin on a bracket, in the sets
`forkset` screens. The clearances are those `braced` swept for its candidates at the same
width: an arm is the part itself (a link) or the arm of a plate between the same joints, and
its copies share its clearances. A single fork is not searched when it does not layer even
with no ground pins at all. No part but the crank is cut at the motor pivot: the crank must
turn on a pin in the frame (or its own rod), where the motor is. `fork_search` is the same
search on candidates another construction has changed (`turntable`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .braced import best_brackets, swept_candidates
from .forkset import fork_sets
from .layers import (
    Arm,
    Bracket,
    Conflicts,
    Fork,
    Layout,
    NoFlatLayers,
    Shaft,
    stack_layers,
)
from .options import Sizes
from .parts import Assembly, Pin

MAX_FORKS = 60  # single forks' layer searches per width before sets of forks are tried
MAX_SETS = 4  # sets of forks tried per width, each as `forkset` screens them


@dataclass
class _Problem:
    """A layer search with some parts forked. `keep`: the union candidate each of its parts is
    (a forked part's copies repeat one); `copies`: (forked part, joint, the part carried there
    or None, index) of each copy; `real`: a real pin's pin in the search; `rods`: a real pin
    cut into rods, as (the part carried, its pin in the search); `shafts`: each forked part's
    pin in the search its copies are fixed on."""

    keep: list[int] = field(default_factory=list)
    pins: list[Pin] = field(default_factory=list)
    blocked: list[list[int]] = field(default_factory=list)
    whole: list[int] = field(default_factory=list)
    copies: list[tuple[int, int, int | None, int]] = field(default_factory=list)
    real: dict[int, int] = field(default_factory=dict)
    rods: dict[int, list[tuple[int, int]]] = field(default_factory=dict)
    shafts: dict[int, int] = field(default_factory=dict)

    def arms(self, part: int | None = None) -> list[int]:
        """The copies' indices among the search's parts (of one forked part)."""
        return [c for p, _, _, c in self.copies if part in (None, p)]


def forked_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with one part forked (and at most one ground pin on a bracket), within MAX_FORKS
    layer searches, else with one of the first MAX_SETS sets of forks `forkset` screens.
    ValueError when none layers."""
    candidates = swept_candidates(assembly, paths, sizes)
    return fork_search(assembly, candidates, len(paths), sizes, drivable)


def fork_search(
    assembly: Assembly,
    candidates: tuple[Assembly, list[tuple], np.ndarray, Conflicts],
    first: int,
    sizes: Sizes,
    allowed: Callable[[Assembly, tuple[int, int]], bool],
    brackets: bool = True,
    cut: bool = False,
) -> Layout:
    """`forked_layers` on given candidates (`braced.swept_candidates`, their posts' joints from
    `first` on), with the forks `allowed` allows, and brackets only where `brackets`. cut: the
    crank forked at the motor may have its shaft cut into stubs from base and cover (its
    halves turned as one by `drive`)."""
    ground = tuple(pin.joint for pin in assembly.pins if 0 in pin.members)
    union, roles, posts, conflicts = candidates
    bracket = best_brackets(conflicts, roles) if brackets else {}
    moving = sorted(range(1, len(assembly.parts)), key=lambda q: len(assembly.parts[q].joints))
    forks = [((q, s),) for q in moving for s in assembly.parts[q].joints]
    forks = [fork for fork in forks if allowed(assembly, fork[0])]
    searches, refusal = 0, None

    def search(chosen: tuple, held: int | None, relaxed: bool = False):
        nonlocal searches, refusal
        searches += 1
        problem = _problem(assembly, union, conflicts, roles, chosen, held, bracket, relaxed, cut)
        try:
            return problem, _layered(problem, union, conflicts, sizes, fewest=not relaxed)
        except NoFlatLayers as exc:
            refusal = refusal or exc
            if relaxed:
                forks.remove(chosen)
            return None

    for fork in forks[:MAX_FORKS]:  # first the bound: no ground pins at all
        search(fork, None, relaxed=True)
    held_by = [None, *(g for g in ground if g in bracket)]
    tries = [(fork, held) for held in held_by for fork in forks]
    for fork, held in tries[: MAX_FORKS - searches]:
        found = search(fork, held)
        if found is not None:
            return _real(assembly, found[1], found[0], roles, posts, fork, first)
    sets = fork_sets(assembly, union, roles, conflicts, allowed, bracket, MAX_SETS, cut)
    for chosen, held in sets:
        found = search(chosen, held)
        if found is not None:
            return _real(assembly, found[1], found[0], roles, posts, chosen, first)
    raise refusal or ValueError("no forked part layers")


def drivable(assembly: Assembly, fork: tuple[int, int]) -> bool:
    """Whether a motor in the frame still drives the crank: a fork of another part may not
    cut the pin at the motor pivot, where the crank would turn on a rod of that part."""
    part, shaft = fork
    cut = set(assembly.parts[part].joints) - {shaft}
    return part == assembly.crank.child or assembly.crank.joint not in cut


def _problem(
    assembly: Assembly,
    union: Assembly,
    conflicts: Conflicts,
    roles: list[tuple],
    forks: tuple[tuple[int, int], ...],
    held: int | None,
    bracket: dict[int, int],
    relaxed: bool = False,
    cut: bool = False,
) -> _Problem:
    """The search with each part `fork[0]` forked at joint `fork[1]` (forks sharing no joint),
    ground pin `held` (if any) on its bracket; relaxed: no ground pins at all, a bound on every
    way to hold them; cut: the crank's shaft at the motor may be cut into stubs."""
    index = {role[1]: u for u, role in enumerate(roles) if role[0] == "part"}
    arm = {(role[1], role[2]): u for u, role in enumerate(roles) if role[0] == "arm"}
    forked_parts = {p for p, _ in forks}
    problem = _Problem(keep=[u for q, u in index.items() if q not in forked_parts])
    if held is not None:
        problem.keep.append(bracket[held])
    geometry: dict[int, list[int]] = {}  # union candidate -> the copies made of it
    for part, shaft in forks:
        forked = assembly.parts[part]
        for j in (j for j in forked.joints if j != shaft):
            u = index[part] if forked.kind == "link" else arm[(part, tuple(sorted((shaft, j))))]
            carries = [q for q, o in enumerate(assembly.parts) if j in o.joints and q != part]
            for carried in carries or [None]:  # a joint of its own (an end effector): one arm
                geometry.setdefault(u, []).append(len(problem.keep))
                problem.copies.append((part, j, carried, len(problem.keep)))
                problem.keep.append(u)
    copies = problem.arms()
    where = {u: k for k, u in enumerate(problem.keep) if k not in copies}
    grounds = {pin.joint for pin in assembly.pins if 0 in pin.members}
    cut = {j for p, s in forks for j in assembly.parts[p].joints if j != s}  # rods there

    def mapped(k: int, exempt: tuple[int, ...] = ()) -> list[int]:
        near = conflicts.blocked[k]
        copied = [c for u in near for c in geometry.get(u, ()) if c not in exempt]
        return [where[u] for u in near if u in where] + copied

    for k, pin in enumerate(union.pins):
        j, real = pin.joint, k < len(assembly.pins)
        kept = real or pin.name.startswith(("shaft_", "lug"))  # a real pin, a plate's own
        # shaft, or a ground ring's lug post (`forked_rings`)
        if pin.name.startswith("post"):
            if held is not None and bracket[held] in pin.members:
                _add(problem, pin, [0, where[bracket[held]]], mapped(k))
            continue
        if relaxed and j in grounds:
            continue  # the bound: held in any way at all
        members = [where[u] for u in pin.members if u and u in where and roles[u][0] == "part"]
        if 0 in pin.members:
            members.insert(0, where[bracket[held]] if j == held else 0)
        shafted = [p for p, s in forks if s == j]
        if shafted and kept:
            shaft = _add(problem, pin, members + problem.arms(shafted[0]), mapped(k))
            problem.shafts[shafted[0]] = shaft
            if not (cut and j == assembly.crank.joint):
                problem.whole.append(shaft)
            problem.real[k] = shaft
        elif j in cut and real:
            here = tuple(c for _, joint, _, c in problem.copies if joint == j)
            for _, joint, carried, c in problem.copies:
                if joint == j and carried is not None:
                    own = members[0] if carried == 0 else where[index[carried]]
                    others = [m for m in members if m not in (own, 0)]
                    rod = _add(problem, pin, [c, own], mapped(k, here) + others)
                    problem.rods.setdefault(k, []).append((carried, rod))
        elif kept and len(members) >= 2:
            problem.real[k] = _add(problem, pin, members, mapped(k))
    return problem


def _add(problem: _Problem, pin: Pin, members: list[int], near: list[int]) -> int:
    """Append a pin of the search; its index."""
    problem.pins.append(Pin(pin.name, pin.joint, members[0], tuple(members)))
    problem.blocked.append(near)
    return len(problem.pins) - 1


def _layered(
    problem: _Problem, union: Assembly, conflicts: Conflicts, sizes: Sizes, fewest: bool = True
) -> Layout:
    """stack_layers on the forks' candidates: a part's copies share its clearances and may
    not share a layer with each other (fewest: as there)."""
    sub = np.ix_(problem.keep, problem.keep)
    near, distance = conflicts.parts[sub].copy(), conflicts.distance[sub].copy()
    for part in {p for p, _, _, _ in problem.copies}:
        copies = problem.arms(part)
        near[np.ix_(copies, copies)] = True
        distance[np.ix_(copies, copies)] = 0.0
        near[copies, copies] = False
    chosen = Assembly([union.parts[u] for u in problem.keep], [], problem.pins, [])
    return stack_layers(chosen, Conflicts(near, problem.blocked, distance), sizes, stubs=True,
                        whole=problem.whole, fewest=fewest)  # fmt: skip


def _real(
    assembly: Assembly,
    layout: Layout,
    problem: _Problem,
    roles: list[tuple],
    posts: np.ndarray,
    forks: tuple[tuple[int, int], ...],
    first: int,
) -> Layout:
    """The layout of the real parts: each forked part's arms (its layer their lowest), the
    rods its pins are cut into, its shaft where no pin was, the bracket and where its post goes
    (joint `first + k` for post k)."""
    layers = np.zeros(len(assembly.parts), int)
    for k, u in enumerate(problem.keep):
        if roles[u][0] == "part" and roles[u][1]:
            layers[roles[u][1]] = layout.layers[k]
    arms, shafts = {}, []
    for part, shaft in forks:
        arms[part] = tuple(Arm(tuple(sorted((shaft, j))), int(layout.layers[c]))
                           for p, j, _, c in problem.copies if p == part)  # fmt: skip
        layers[part] = min(a.layer for a in arms[part])
        s = problem.shafts.get(part)
        if s is not None and problem.pins[s].name.startswith("shaft_"):
            shafts.append(Shaft(part, shaft, layout.pin_spans[s]))
    spans = [(0, 0)] * len(assembly.pins)
    stubs = {}
    for k, s in problem.real.items():
        if k < len(assembly.pins):
            spans[k] = layout.pin_spans[s]
            if s in layout.cover_stubs:
                stubs[k] = layout.cover_stubs[s]
    forked = {j: p for p, s in forks for j in assembly.parts[p].joints if j != s}
    cuts = {}
    for k, rods in problem.rods.items():
        merged = _merged([((carried,), layout.pin_spans[s]) for carried, s in rods])
        cuts[k] = Fork(forked[assembly.pins[k].joint], merged)
        spans[k] = (cuts[k].rods[0][1][0], max(hi for _, (_, hi) in cuts[k].rods))
    brackets = tuple(
        Bracket(roles[u][1], tuple(map(float, posts[roles[u][2]])), int(layout.layers[k]),
                first + roles[u][2] in layout.top_joints)
        for k, u in enumerate(problem.keep) if roles[u][0] == "bracket")  # fmt: skip
    top = tuple(j for j in layout.top_joints if j < first)
    return Layout(layers, spans, top, layout.count, layout.min_gap, layout.minimal,
                  arms=arms, brackets=brackets, shafts=tuple(shafts), cover_stubs=stubs,
                  forks=cuts)  # fmt: skip


def _merged(rods: list[tuple[tuple[int, ...], tuple[int, int]]]) -> tuple:
    """Coaxial rods that overlap in z made one rod (through the parts of both), bottom up."""
    out: list = []
    for parts, (lo, hi) in sorted(rods, key=lambda rod: rod[1]):
        if out and lo <= out[-1][1][1]:
            (before, (low, high)) = out.pop()
            parts, lo, hi = before + parts, low, max(high, hi)
        out.append((parts, (lo, hi)))
    return tuple(out)
