"""Dyadic assembly of a batch of linkage graphs: which joint is solved from which two.

Convention shared by the whole package: in a batch, node 0 is the motor pivot and node 1 the
crank tip. The known set starts as the fixed joints plus the crank tip; a free joint becomes
known when exactly two of its links reach known joints (a dyad). A free joint with more than two
links to known joints is over-constrained; unknown joints left with no dyad to close mean the
graph is not dyadic (it has extra degrees of freedom). Joints are added one at a time, lowest
index first, so a link between two joints that become solvable together is counted.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np


class Status(IntEnum):
    """Validation verdicts, in the order they are checked (the first failing one is reported)."""

    VALID = 0
    BAD_MOTOR = 1
    OVERCONSTRAINED = 2
    NOT_DYADIC = 3
    ZERO_LENGTH_LINK = 4
    COINCIDENT_JOINTS = 5
    LOCKS = 6

    @property
    def reason(self) -> str:
        return _REASONS[self]


_REASONS = {
    Status.VALID: "valid",
    Status.BAD_MOTOR: "the motor pivot must be fixed, the crank tip free and linked to the pivot",
    Status.OVERCONSTRAINED: "over-constrained: a joint has more than two links to known joints",
    Status.NOT_DYADIC: "not dyadic: some joints cannot be reached through two known joints",
    Status.ZERO_LENGTH_LINK: "a link has zero length",
    Status.COINCIDENT_JOINTS: "two joints coincide in the assembly pose",
    Status.LOCKS: "the mechanism locks: a dyad cannot close at some crank angle",
}


@dataclass
class Plan:
    """Solve order of a batch. Step s solves `dyad_node[:, s]` from `dyad_parents[:, s]`.

    Unused steps point at the scratch slot N with parents (0, 1); kinematics writes there
    harmlessly, so every batch member runs the same number of steps.
    """

    status: np.ndarray  # (B,) int, Status codes (topological part only)
    dyad_node: np.ndarray  # (B, S) int in 0..N (N = scratch)
    dyad_parents: np.ndarray  # (B, S, 2) int, ascending parent indices


def assembly_plan(adjacency: np.ndarray, fixed: np.ndarray, valid: np.ndarray) -> Plan:
    """Topological validation and solve order for (B, N, N) links, (B, N) fixed and valid masks."""
    adjacency = np.asarray(adjacency, dtype=bool)
    valid = np.asarray(valid, dtype=bool)
    fixed = np.asarray(fixed, dtype=bool) & valid
    bsz, n = valid.shape
    adj = adjacency & valid[:, :, None] & valid[:, None, :]
    rows = np.arange(bsz)

    status = np.zeros(bsz, dtype=np.int64)
    motor_ok = valid[:, 0] & valid[:, 1] & fixed[:, 0] & ~fixed[:, 1] & adj[:, 0, 1]
    status[~motor_ok] = Status.BAD_MOTOR
    # The crank tip may hang on the pivot alone: any other fixed joint on it locks the crank.
    tip_over = (adj[:, 1] & fixed).sum(1) > 1
    status[(status == 0) & tip_over] = Status.OVERCONSTRAINED

    known = fixed.copy()
    known[:, 1] |= valid[:, 1]
    steps = max(n - 2, 0)
    dyad_node = np.full((bsz, steps), n, dtype=np.int64)
    dyad_parents = np.zeros((bsz, steps, 2), dtype=np.int64)
    dyad_parents[:, :, 1] = 1
    over = np.zeros(bsz, dtype=bool)
    count = (adj & known[:, None, :]).sum(2, dtype=np.int16)
    for s in range(steps):
        unknown = valid & ~known
        over |= (unknown & (count > 2)).any(1)
        candidate = unknown & (count == 2)
        has = candidate.any(1)
        if not has.any():
            break
        node = candidate.argmax(1)
        new_links = adj[rows, node] & has[:, None]
        linked = new_links & known
        first = linked.argmax(1)
        linked[rows, first] = False
        dyad_node[has, s] = node[has]
        dyad_parents[has, s, 0] = first[has]
        dyad_parents[has, s, 1] = linked.argmax(1)[has]
        known[rows[has], node[has]] = True
        count += new_links
    status[(status == 0) & over] = Status.OVERCONSTRAINED
    status[(status == 0) & (valid & ~known).any(1)] = Status.NOT_DYADIC
    used = int((dyad_node < n).sum(1).max(initial=0))
    return Plan(status, dyad_node[:, :used], dyad_parents[:, :used])
