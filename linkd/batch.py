"""A padded batch of linkages as plain arrays, the form kinematics and validation work on."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from linkd.graph import ADJ, FEATURES, TYPE, VALID, XY, decode
from linkd.mechanism import Mechanism


@dataclass
class LinkageBatch:
    """B linkages padded to N joints; joint 0 is each motor pivot and joint 1 its crank tip."""

    positions: np.ndarray  # (B, N, 2) float64, assembly pose
    fixed: np.ndarray  # (B, N) bool
    valid: np.ndarray  # (B, N) bool, False for padding
    adjacency: np.ndarray  # (B, N, N) bool, symmetric
    end_effector: np.ndarray  # (B,) int

    def __len__(self) -> int:
        return len(self.positions)

    @classmethod
    def from_graphs(cls, graphs: np.ndarray) -> LinkageBatch:
        """Decode (B, N, 24) graph matrices; each end effector is its graph's last joint."""
        valid, fixed, positions, adjacency = decode(graphs)
        end_effector = np.maximum(valid.sum(1) - 1, 0)
        return cls(positions, fixed, valid, adjacency, end_effector)

    @classmethod
    def from_mechanisms(cls, mechanisms: Sequence[Mechanism]) -> LinkageBatch:
        """Pad mechanisms into one batch, relabelling each so its motor comes first."""
        n = max(m.n_nodes for m in mechanisms)
        b = len(mechanisms)
        batch = cls(
            np.zeros((b, n, 2)),
            np.zeros((b, n), bool),
            np.zeros((b, n), bool),
            np.zeros((b, n, n), bool),
            np.zeros(b, int),
        )
        for row, mech in enumerate(mechanisms):
            pivot, tip = mech.motor
            order = [pivot, tip, *(k for k in range(mech.n_nodes) if k not in (pivot, tip))]
            m = mech.relabelled(order)
            k = m.n_nodes
            batch.positions[row, :k] = m.positions
            batch.fixed[row, :k] = m.fixed
            batch.valid[row, :k] = True
            batch.adjacency[row, :k, :k] = m.adjacency()
            batch.end_effector[row] = m.end_effector
        return batch

    def to_graphs(self) -> np.ndarray:
        """(B, N, 24) graph matrices of linkages in graph order (motor first, parents before
        children, end effector last): the inverse of `from_graphs`."""
        b, n = self.valid.shape
        graphs = np.full((b, n, FEATURES), -1.0, np.float32)
        graphs[..., VALID] = self.valid
        graphs[..., TYPE] = np.where(self.valid, self.fixed, -1)
        graphs[..., XY] = np.where(self.valid[..., None], self.positions, 0)
        lower = np.tril(np.ones((n, n), bool), -1) & self.valid[:, :, None]
        graphs[..., ADJ.start : ADJ.start + n] = np.where(lower, self.adjacency, -1)
        return graphs

    def sub_mechanisms(self, rows: np.ndarray, joints: np.ndarray) -> LinkageBatch:
        """For each pair (rows[i], joints[i]), the linkage of that joint and the joints it hangs
        on (down to the crank and the ground), with that joint as end effector. In a linkage of
        dyadic order (parents first, as decoded from graph matrices) this is a valid linkage
        again, and the chosen joint comes last."""
        needed = ancestors(self.adjacency[rows], joints)
        order = np.argsort(~needed, axis=1, kind="stable")  # needed joints first, in order
        pick = order[:, :, None]
        adjacency = np.take_along_axis(self.adjacency[rows], pick, 1)
        adjacency = np.take_along_axis(adjacency, order[:, None, :], 2)
        valid = np.take_along_axis(needed, order, 1)
        return LinkageBatch(
            np.take_along_axis(self.positions[rows], pick, 1),
            np.take_along_axis(self.fixed[rows], order, 1) & valid,
            valid,
            adjacency & valid[:, :, None] & valid[:, None, :],
            valid.sum(1) - 1,
        )

    def subset(self, index: np.ndarray | slice) -> LinkageBatch:
        return LinkageBatch(
            self.positions[index],
            self.fixed[index],
            self.valid[index],
            self.adjacency[index],
            self.end_effector[index],
        )


def ancestors(adjacency: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(K, N) the joints each of `joints` (K,) hangs on, itself and the motor included, in
    linkages of dyadic order (parents come first) with links `adjacency` (K, N, N)."""
    n = adjacency.shape[1]
    parents = np.tril(adjacency, -1)
    needed = np.zeros((len(joints), n), bool)
    needed[np.arange(len(joints)), joints] = True
    needed[:, :2] = True  # the motor
    for _ in range(n):  # each pass adds the parents of what is needed
        needed |= (parents & needed[:, :, None]).any(1)
    return needed
