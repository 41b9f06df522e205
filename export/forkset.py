"""Which parts to fork at once: one satisfiability problem over every fork there could be.

Where no single fork lets the stack layer, several may: each cuts the pins at its part's
carried joints, so other parts may pass between the rods there. The forks worth trying
together are too many to search one set at a time, so one SAT problem holds them all: a
literal per part and shaft joint (or whole), every plate each choice would make with its
layer written in order (levels 1..LEVELS, ties allowed), and each pin's rule guarded by the
choices that make it: a pin of whole parts, the shaft pin of a fork, or a fork's rods at a
joint it carries. The plates' clearances are the candidates' of `braced.swept_candidates`,
as `forked` searches them. Forks share no joint (two parts fixed on one shaft would turn as
one), none but the crank's cuts the motor pivot, and each ground pin's parts may be held from
the base or the cover (stubs), all of them from the same plate at a fork's shaft (but the
crank's arms at the motor, each from either, where its shaft may be cut: `cut`), or, at one
ground pin at most, from its bracket (`braced.best_brackets`: a ground plate inside the stack,
on a post from the base or the cover), as `forked` can hold one.

What it answers is a screen, not a layout: parts on one layer may still clash, which the real
search of `forked` then settles, so each set it passes is made minimal and several are tried.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from itertools import combinations, count

import numpy as np
from pysat.solvers import Solver

from .exact import SOLVER
from .layers import Conflicts
from .parts import Assembly

LEVELS = 24  # layers the screen allows: more than any mechanism built so far takes
BRACKET = -1  # a bracket's part among the plates


def fork_sets(
    assembly: Assembly,
    union: Assembly,
    roles: list[tuple],
    conflicts: Conflicts,
    drivable: Callable[[Assembly, tuple[int, int]], bool],
    bracket: dict[int, int],
    tries: int,
    cut: bool = False,
) -> Iterator[tuple[tuple[tuple[int, int], ...], int | None]]:
    """Up to `tries` sets of forks (part, shaft joint), each with the ground joint held on its
    `bracket` candidate (or None), that pass the screen, each minimal (no fork of it can be
    left whole, nor the bracket left out), as the solver finds them; none if none passes. A
    fork is (part, shaft) as `drivable` allows it. cut: the crank forked at the motor may have
    its arms held from both the base and the cover (its shaft cut in two, `drive`)."""
    problem = _Screen(assembly, union, roles, conflicts, drivable, bracket, cut)
    forks = [(fork, lit) for fork, lit in problem.choice.items() if fork[1] is not None]
    forks += [((0, joint), lit) for joint, lit in problem.held.items()]  # a bracket: (0, joint)
    with Solver(name=SOLVER, bootstrap_with=problem.clauses) as solver:
        for _ in range(tries):
            if not solver.solve():
                return
            model = set(solver.get_model())
            off = [-lit for _, lit in forks if lit not in model]  # those it left out
            for _, lit in forks:  # then each it took, left out while the rest still pass
                if lit in model and solver.solve(assumptions=[*off, -lit]):
                    off.append(-lit)
            found = [(fork, lit) for fork, lit in forks if -lit not in off]
            held = next((joint for (part, joint), _ in found if part == 0), None)
            yield tuple(fork for fork, _ in found if fork[0]), held
            solver.add_clause([-lit for _, lit in found])


class _Screen:
    """The clauses. Plates: (part, shaft, joint, carried part, candidate, choice literal); a
    whole part has shaft, joint and carried None, a bracket part BRACKET and its joint.
    `cut`: the crank's fork at the motor, where its shaft may be cut (else None)."""

    def __init__(self, assembly, union, roles, conflicts, drivable, bracket, cut=False):
        parts = assembly.parts
        self.parts = parts
        self.cut = (assembly.crank.child, assembly.crank.joint) if cut else None
        index = {role[1]: u for u, role in enumerate(roles) if role[0] == "part"}
        arm = {(role[1], role[2]): u for u, role in enumerate(roles) if role[0] == "arm"}
        self.at: dict[int, list[int]] = {}
        for p, part in enumerate(parts):
            for j in part.joints:
                self.at.setdefault(j, []).append(p)
        self.pin, self.post = {}, {}  # the candidates near each joint's pin, each post
        for pin, near in zip(union.pins, conflicts.blocked):
            if pin.name.startswith("post"):
                self.post[pin.members[1]] = set(near)
            else:
                self.pin[pin.joint] = set(near)
        literal = count(1)
        self.choice = {}
        for p in range(1, len(parts)):
            self.choice[p, None] = next(literal)
            for s in parts[p].joints:
                if drivable(assembly, (p, s)):
                    self.choice[p, s] = next(literal)
        self.plates = []
        for (p, s), lit in self.choice.items():
            if s is None:
                self.plates.append((p, None, None, None, index[p], lit))
                continue
            for c in (c for c in parts[p].joints if c != s):
                u = index[p] if parts[p].kind == "link" else arm[p, tuple(sorted((s, c)))]
                for carried in [q for q in self.at[c] if q != p] or [None]:
                    self.plates.append((p, s, c, carried, u, lit))
        self.held = {}  # ground joint -> the literal: its bracket holds it
        for joint, u in bracket.items():
            self.held[joint] = next(literal)
            self.plates.append((BRACKET, None, joint, None, u, self.held[joint]))
        n = len(self.plates)
        first = next(literal)
        self.fresh = count(first + n * (LEVELS - 1))
        false, true = next(self.fresh), next(self.fresh)
        self.upto = np.empty((n, LEVELS + 1), int)  # [p, l]: the literal "p's level <= l"
        self.upto[:, 0], self.upto[:, LEVELS] = false, true
        self.upto[:, 1:LEVELS] = np.arange(n * (LEVELS - 1)).reshape(n, LEVELS - 1) + first
        ordered = np.stack([-self.upto[:, 1:-2], self.upto[:, 2:-1]], -1)  # <= l: <= l + 1
        self.clauses = [[-false], [true], *ordered.reshape(-1, 2).tolist()]
        self.below: list[tuple[int, int, tuple[int, ...]]] = []  # (p, q, unless) of `_below`
        self._choices()
        for joint in self.at:
            self._joint(joint)
        self._orders()

    def _below(self, p: int, q: int, *unless: int) -> None:
        """Plate p on a lower level than q, unless one of the literals holds."""
        self.below.append((p, q, unless))

    def _orders(self) -> None:
        """The clauses of every `_below`: a literal per ordered pair of plates, "p lies below
        q" (q at most l implies p at most l - 1, level by level), and each rule's clause that
        it holds unless one of the rule's literals does. Rules share pairs, so this is a
        fraction of the clauses of writing every rule level by level."""
        pairs: dict[tuple[int, int], int] = {}
        for p, q, unless in self.below:
            if (p, q) not in pairs:
                pairs[p, q] = next(self.fresh)
            self.clauses.append([*unless, pairs[p, q]])
        if not pairs:
            return
        p, q = np.array(list(pairs)).T
        rows = np.empty((len(pairs), LEVELS, 3), int)
        rows[..., 0] = -np.array(list(pairs.values())).reshape(-1, 1)
        rows[..., 1] = -self.upto[q, 1:]
        rows[..., 2] = self.upto[p, :-1]
        self.clauses += rows.reshape(-1, 3).tolist()

    def _apart(self, plate: int, members: list[tuple[int, int]], *unless: int) -> None:
        """The plate below all the members (plate, literal that it is made) or above all."""
        side = next(self.fresh)
        for m, made in members:
            self._below(plate, m, *unless, -made, -self.plates[plate][5], -side)
            self._below(m, plate, *unless, -made, -self.plates[plate][5], side)

    def _choices(self) -> None:
        """One choice per part; forks share no joint."""
        for p in range(1, len(self.parts)):
            mine = [lit for (q, _), lit in self.choice.items() if q == p]
            self.clauses += [mine, *([-a, -b] for a, b in combinations(mine, 2))]
        forks = [(p, lit) for (p, s), lit in self.choice.items() if s is not None]
        for (p, a), (q, b) in combinations(forks, 2):
            if p != q and set(self.parts[p].joints) & set(self.parts[q].joints):
                self.clauses.append([-a, -b])
        self.clauses += [[-a, -b] for a, b in combinations(self.held.values(), 2)]
        for (p, s), lit in self.choice.items():  # a fork's rod there or the bracket, not both
            self.clauses += [[-lit, -self.held[j]] for j in self.parts[p].joints
                             if s is not None and j != s and j in self.held]  # fmt: skip

    def _near(self, plate: int, joint: int) -> bool:
        """Whether the plate comes near the pin at `joint` (one of its own joints: never)."""
        p, shaft, end, _, u, _ = self.plates[plate]
        own = joint == shaft or (shaft is None and p != BRACKET and joint in self.parts[p].joints)
        return not own and joint != end and u in self.pin.get(joint, ())

    def _joint(self, joint: int) -> None:
        """The rules of the pin at `joint`: whole, or cut into rods by a fork carrying it."""
        there = self.at[joint]
        moving = [p for p in there if p]
        cuts = [(p, s) for p in moving for s in self.parts[p].joints
                if s != joint and (p, s) in self.choice]  # fmt: skip
        unless = [self.choice[cut] for cut in cuts]
        members = [(k, plate[5], plate[0]) for k, plate in enumerate(self.plates)
                   if plate[0] in moving and plate[1] in (None, joint)]  # fmt: skip
        near = [k for k, plate in enumerate(self.plates)
                if plate[0] not in there and self._near(k, joint)]  # fmt: skip
        if len(there) == 1:  # a joint of one part: a pin only as a fork's shaft
            members = [m for m in members if self.plates[m[0]][1] == joint]
        if 0 in there:
            side = {p: next(self.fresh) for p in moving}
            for p in moving:
                if (p, joint) in self.choice and (p, joint) != self.cut:  # its shaft: every
                    # part held from one plate
                    fork = self.choice[p, joint]
                    self.clauses += [c for q in moving if q != p
                                     for c in ([-fork, -side[p], side[q]],
                                               [-fork, side[p], -side[q]])]  # fmt: skip
            held = [self.held[joint]] if joint in self.held else []  # stubs unless bracketed
            for m, made, p in members:
                own = next(self.fresh) if (p, joint) == self.cut else side[p]  # an arm's stub
                for b in near:
                    b_made = self.plates[b][5]
                    self._below(m, b, *unless, *held, -made, -b_made, -own)
                    self._below(b, m, *unless, *held, -made, -b_made, own)
            if held:
                self._bracket(joint, [(m, made) for m, made, _ in members], near)
        elif len(members) >= 2 or len(there) == 1:
            for b in near:
                self._apart(b, [(m, made) for m, made, _ in members], *unless)
        for p, s in cuts:
            self._rods(joint, p, s, near)

    def _bracket(self, joint: int, members: list[tuple[int, int]], near: list[int]) -> None:
        """The ground pin at `joint` held on its bracket: a pin between the bracket and the
        parts there, and the bracket's post from the base or the cover, clear of the plates that
        come near it."""
        held = self.held[joint]
        bracket = next(k for k, (part, _, end, _, _, _) in enumerate(self.plates)
                       if part == BRACKET and end == joint)  # fmt: skip
        for b in near:
            self._apart(b, [(bracket, held), *members], -held)
        side = next(self.fresh)  # true: the post stands in the base
        for b, plate in enumerate(self.plates):
            if plate[4] in self.post[self.plates[bracket][4]]:
                self._below(bracket, b, -held, -plate[5], -side)
                self._below(b, bracket, -held, -plate[5], side)

    def _rods(self, joint: int, part: int, shaft: int, near: list[int]) -> None:
        """Fork (part, shaft) carries `joint`: a rod per part carried there, from its arm to
        that part (or the ground), clear of whatever comes near and of the other parts there."""
        fork = self.choice[part, shaft]
        for k, (p, s, end, carried, _, _) in enumerate(self.plates):
            if (p, s, end) != (part, shaft, joint) or carried is None:
                continue
            own = [(m, plate[5]) for m, plate in enumerate(self.plates)
                   if carried and plate[0] == carried and plate[1] is None]  # fmt: skip
            others = [m for m, plate in enumerate(self.plates)
                      if plate[0] not in (0, part, carried) and plate[0] in self.at[joint]
                      and plate[1] is None]  # fmt: skip
            mine = [m for m, plate in enumerate(self.plates)
                    if plate[:2] == (part, shaft) and plate[2] != joint
                    and plate[4] in self.pin.get(joint, ())]  # fmt: skip
            blocked = near + others + mine  # mine: its other arms that pass by
            if carried == 0:  # held from the base or the cover
                side = next(self.fresh)
                for b in blocked:
                    self._below(k, b, -fork, -self.plates[b][5], -side)
                    self._below(b, k, -fork, -self.plates[b][5], side)
                continue
            for b in blocked:
                self._apart(b, [(k, fork), *own], -fork)
