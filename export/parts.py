"""Split a mechanism into rigid parts and join them as a tree of hinges closed by pin equalities.

A part is a set of joints that move as one rigid body: the ground frame (every fixed joint), a
binary link, or a plate (three or more joints held rigid by triangles of links, such as a ternary
coupler). Parts meet at pins. A breadth-first tree from the ground gives each moving part one
hinge about z; every other part meeting at a pin is tied to it by a loop closure.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from linkd.batch import LinkageBatch
from linkd.kinematics import trace
from linkd.mechanism import Mechanism
from linkd.topology import assembly_plan

CRANK = "crank"  # the motor hinge's name (CONTRACT §3)


@dataclass(frozen=True)
class Part:
    """A rigid body of the mechanism: 'ground', 'link' (two joints) or 'plate' (three or more)."""

    name: str
    kind: str
    joints: tuple[int, ...]
    links: tuple[tuple[int, int], ...] = ()  # a plate's: the mechanism's links holding it rigid


@dataclass(frozen=True)
class Hinge:
    """The tree joint of `child`: a hinge about z at mechanism joint `joint`, on part `parent`."""

    name: str
    child: int
    parent: int
    joint: int


@dataclass(frozen=True)
class Pin:
    """A pin at a mechanism joint shared by several parts; `hub` carries it, the rest turn on it."""

    name: str
    joint: int
    hub: int
    members: tuple[int, ...]  # every part at the joint, hub included


@dataclass(frozen=True)
class Loop:
    """A loop closure: part `part` is held on the pin of `hub` at mechanism joint `joint`."""

    name: str
    part: int
    hub: int
    joint: int


@dataclass(frozen=True)
class Assembly:
    parts: list[Part]  # ground first
    hinges: list[Hinge]  # one per moving part, parents before children
    pins: list[Pin]
    loops: list[Loop]

    @property
    def crank(self) -> Hinge:
        """The motor's hinge: its joint is the motor pivot, its child the crank."""
        return next(h for h in self.hinges if h.name == CRANK)


def rigid_parts(mech: Mechanism) -> list[Part]:
    """Group joints into rigid bodies: links merge when they form a triangle or share two joints."""
    fixed = set(np.flatnonzero(mech.fixed).tolist())
    clusters = [fixed] + [{i, j} for i, j in mech.links if not (i in fixed and j in fixed)]
    while _merge_rigid(clusters):
        pass
    ground = Part("ground", "ground", tuple(sorted(clusters[0])))
    moving = sorted(tuple(sorted(c)) for c in clusters[1:])
    names = [("link_" if len(j) == 2 else "plate_") + "_".join(map(str, j)) for j in moving]
    kinds = ["link" if len(j) == 2 else "plate" for j in moving]
    links = [tuple(e for e in mech.links if len(j) > 2 and set(e) <= set(j)) for j in moving]
    return [ground, *(Part(*fields) for fields in zip(names, kinds, moving, links))]


def _merge_rigid(clusters: list[set[int]]) -> bool:
    """Merge one group of clusters that is rigid together; False when none is left.

    Two rigid bodies pinned at two joints are one body; three bodies pinned pairwise at three
    different joints form a triangle, also one body. Merging keeps the lower index (ground 0).
    """
    for a, b in combinations(range(len(clusters)), 2):
        if len(clusters[a] & clusters[b]) >= 2:
            _absorb(clusters, a, [b])
            return True
    for a, b, c in combinations(range(len(clusters)), 3):
        shared = [clusters[a] & clusters[b], clusters[b] & clusters[c], clusters[a] & clusters[c]]
        if all(shared) and len(set.union(*shared)) == 3:
            _absorb(clusters, a, [b, c])
            return True
    return False


def _absorb(clusters: list[set[int]], keep: int, others: list[int]) -> None:
    for k in sorted(others, reverse=True):
        clusters[keep] |= clusters.pop(k)


def assemble(mech: Mechanism) -> Assembly:
    """Parts, the hinge tree (breadth first from the ground), pins and loop closures.

    The first part reached at a joint is its hub: it carries the pin; parts it reaches through
    that joint hang on it by hinges, parts reached earlier by another way close a loop onto it.
    Raises ValueError when the hinges minus two per loop closure do not leave one freedom.
    """
    parts = rigid_parts(mech)
    at_joint: dict[int, list[int]] = {}
    for p, part in enumerate(parts):
        for j in part.joints:
            at_joint.setdefault(j, []).append(p)
    pivot, tip = mech.motor
    hub: dict[int, int] = {}
    hinges: list[Hinge] = []
    reached, queue = {0}, [0]
    while queue:
        parent = queue.pop(0)
        for j in parts[parent].joints:
            hub.setdefault(j, parent)
            if hub[j] != parent:
                continue
            for child in at_joint[j]:
                if child in reached:
                    continue
                reached.add(child)
                queue.append(child)
                crank = j == pivot and tip in parts[child].joints
                name = CRANK if crank else f"hinge_{parts[child].name}"
                hinges.append(Hinge(name, child, parent, j))
    if len(reached) < len(parts):
        raise ValueError("some parts are not connected to the ground")
    tree = {(h.child, h.joint) for h in hinges}
    pins, loops = [], []
    for j, members in sorted(at_joint.items()):
        if len(members) < 2:
            continue
        pins.append(Pin(f"pin_{j}", j, hub[j], tuple(members)))
        for p in members:
            if p != hub[j] and (p, j) not in tree:
                loops.append(Loop(f"loop_{j}_{parts[p].name}", p, hub[j], j))
    if not any(h.name == CRANK for h in hinges):
        raise ValueError("the crank is not a part turning on the motor pivot")
    if len(hinges) - 2 * len(loops) != 1:
        raise ValueError(
            f"{len(hinges)} hinges and {len(loops)} loop closures do not leave one freedom"
        )
    return Assembly(parts, hinges, pins, loops)


def part_origins(mech: Mechanism, assembly: Assembly) -> np.ndarray:
    """(P, 2) body frame origin of every part: its hinge joint (the ground's is the motor
    pivot, so that meshes, which MuJoCo keeps in single precision, stay near their frame's
    origin even for a mechanism far from the user's)."""
    origins = np.zeros((len(assembly.parts), 2))
    origins[0] = mech.positions[mech.motor[0]]
    for h in assembly.hinges:
        origins[h.child] = mech.positions[h.joint]
    return origins


def joint_paths(mech: Mechanism, angles: np.ndarray) -> np.ndarray:
    """(N, T, 2) analytic joint positions at crank angles relative to the assembly pose."""
    pivot, tip = mech.motor
    order = [pivot, tip, *(k for k in range(mech.n_nodes) if k not in (pivot, tip))]
    batch = LinkageBatch.from_mechanisms([mech])
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    motion = trace(batch.positions, plan, np.asarray(angles, dtype=np.float64))
    paths = np.empty((mech.n_nodes, len(angles), 2))
    paths[order] = np.stack([motion.x[0], motion.y[0]], -1)
    return paths


def part_rotations(assembly: Assembly, paths: np.ndarray) -> np.ndarray:
    """(P, T) rotation of every part from its assembly pose, from two of its joints' paths."""
    turns = np.zeros((len(assembly.parts), paths.shape[1]))
    for p, part in enumerate(assembly.parts):
        if p == 0 or len(part.joints) < 2:
            continue
        a, b = part.joints[:2]
        d = paths[b, :, 0] - paths[a, :, 0] + 1j * (paths[b, :, 1] - paths[a, :, 1])
        turns[p] = np.angle(d * np.conj(d[0]))
    return turns


def hinge_angles(mech: Mechanism, angles: np.ndarray) -> dict[str, np.ndarray]:
    """Each hinge's angle (T,) at the given crank angles: the analytic pose in joint space.

    The crank hinge is the crank angle itself; the others are wrapped to (-pi, pi].
    """
    angles = np.asarray(angles, dtype=np.float64)
    assembly = assemble(mech)
    turns = part_rotations(assembly, joint_paths(mech, angles))
    out = {}
    for h in assembly.hinges:
        rel = turns[h.child] - turns[h.parent]
        out[h.name] = angles.copy() if h.name == CRANK else np.angle(np.exp(1j * rel))
    return out
