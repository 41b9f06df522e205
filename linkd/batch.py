"""A padded batch of linkages as plain arrays, the form kinematics and validation work on."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from linkd.graph import decode
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

    def subset(self, index: np.ndarray | slice) -> LinkageBatch:
        return LinkageBatch(
            self.positions[index],
            self.fixed[index],
            self.valid[index],
            self.adjacency[index],
            self.end_effector[index],
        )
