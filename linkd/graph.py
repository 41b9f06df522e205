"""The paper's graph matrix: a mechanism as an N x 24 array the model reads and writes.

Row k describes joint k: [validity, type, x, y, adjacency to joints 0..19]. Validity is 1 for a
joint and 0 for padding; type is 1 for a ground joint, 0 for a moving one, -1 for padding; x, y
lie in [-1, 1]; the adjacency entries are 1 or 0 for earlier joints (j < k) and -1 elsewhere.
Joint 0 is the motor pivot, joint 1 the crank tip, every later moving joint hangs on exactly two
earlier joints, and the last joint is the end effector, so every prefix is a mechanism too.
"""

from __future__ import annotations

import numpy as np

from linkd.geometry import Similarity
from linkd.mechanism import DEFAULT_UNITS, Mechanism
from linkd.topology import Status, assembly_plan

MAX_NODES = 20
FEATURES = 4 + MAX_NODES
VALID, TYPE, XY, ADJ = 0, 1, slice(2, 4), slice(4, FEATURES)


def canonical_order(mech: Mechanism) -> list[int]:
    """Joint order of the graph matrix: pivot, tip, dyads in assembly order, end effector last.

    Ground joints are placed just before the first dyad that hangs on them. Raises ValueError
    for a mechanism that is not dyadic or whose end effector drives other joints.
    """
    pivot, tip = mech.motor
    ee = mech.end_effector
    order = [pivot, tip, *(k for k in range(mech.n_nodes) if k not in (pivot, tip))]
    relabelled = mech.relabelled(order)
    everything = np.ones((1, mech.n_nodes), bool)
    plan = assembly_plan(relabelled.adjacency()[None], relabelled.fixed[None], everything)
    status = Status(int(plan.status[0]))
    if status != Status.VALID:
        raise ValueError(status.reason)
    if mech.fixed[ee]:
        raise ValueError("the end effector is a ground joint")
    if ee == tip and mech.n_nodes > 2:
        raise ValueError("the end effector is the crank tip of a larger mechanism")
    adj = mech.adjacency()
    placed = [pivot, tip]
    known = set(np.flatnonzero(mech.fixed)) | {tip}
    pending = [k for k in range(mech.n_nodes) if not mech.fixed[k] and k != tip]
    while pending:
        ready = [k for k in pending if sum(adj[k, j] for j in known) == 2]
        choice = min((k for k in ready if k != ee), default=ee if ee in ready else None)
        if choice is None or (choice == ee and len(pending) > 1):
            raise ValueError("the end effector drives other joints, so it cannot come last")
        ground = sorted(j for j in known if adj[choice, j] and j not in placed)
        placed += [*ground, choice]
        known.add(choice)
        pending.remove(choice)
    unused_ground = [k for k in range(mech.n_nodes) if k not in placed]
    return placed[:-1] + unused_ground + placed[-1:]


def to_graph(mech: Mechanism, normalise: bool = True) -> tuple[np.ndarray, Similarity]:
    """Graph matrix (MAX_NODES, FEATURES) of a mechanism, and the map from graph to user frame.

    With `normalise`, positions are centred on their bounding box and scaled into [-1, 1];
    otherwise they must already lie there.
    """
    order = canonical_order(mech)
    if len(order) > MAX_NODES:
        raise ValueError(f"{len(order)} joints: the graph matrix holds at most {MAX_NODES}")
    canon = mech.relabelled(order)
    frame = Similarity()
    if normalise:
        lo, hi = canon.positions.min(0), canon.positions.max(0)
        half = float((hi - lo).max()) / 2 or 1.0
        frame = Similarity(half, np.eye(2), (lo + hi) / 2)
    xy = frame.inverse().apply(canon.positions)
    if np.abs(xy).max() > 1 + 1e-9:
        raise ValueError("positions must lie in [-1, 1] to be stored unnormalised")
    n = canon.n_nodes
    graph = np.zeros((MAX_NODES, FEATURES))
    graph[:, TYPE] = -1
    graph[:, ADJ] = -1
    graph[:n, VALID] = 1
    graph[:n, TYPE] = canon.fixed
    graph[:n, XY] = xy
    adj = canon.adjacency()
    for k in range(n):
        graph[k, 4 : 4 + k] = adj[k, :k]
    return graph, frame


def decode(graphs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Threshold (B, N, 24) graph matrices into (valid, fixed, positions, adjacency).

    A graph ends at its first row whose validity is below 0.5; type above 0.5 is ground;
    adjacency entries above 0.5 below the diagonal are links (made symmetric).
    """
    graphs = np.asarray(graphs, dtype=np.float64)
    n = graphs.shape[1]
    valid = np.cumprod(graphs[:, :, VALID] > 0.5, axis=1).astype(bool)
    fixed = (graphs[:, :, TYPE] > 0.5) & valid
    lower = (graphs[:, :, 4 : 4 + n] > 0.5) & np.tril(np.ones((n, n), bool), -1)
    adjacency = (lower | lower.transpose(0, 2, 1)) & valid[:, :, None] & valid[:, None, :]
    return valid, fixed, graphs[:, :, XY], adjacency


def from_graph(
    graph: np.ndarray, frame: Similarity | None = None, units: str = DEFAULT_UNITS
) -> Mechanism:
    """Mechanism of one graph matrix (end effector = last joint), mapped by `frame` if given."""
    valid, fixed, positions, adjacency = (a[0] for a in decode(graph[None]))
    n = int(valid.sum())
    if n < 2:
        raise ValueError("a graph needs at least the motor pivot and the crank tip")
    pos = positions[:n] if frame is None else frame.apply(positions[:n])
    links = tuple(zip(*np.nonzero(np.triu(adjacency[:n, :n]))))
    return Mechanism(pos, fixed[:n], links, (0, 1), n - 1, units)
