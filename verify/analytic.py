"""The analytic motion of a mechanism.json: joint paths and rigid parts, in the file's own labels.

The reference every check and every drawing compares against: `linkd.kinematics.trace`, the same
dyadic solver the designer uses, with the mechanism's joints kept in their original order.
"""

from __future__ import annotations

import numpy as np

from linkd.batch import LinkageBatch
from linkd.kinematics import trace
from linkd.mechanism import Mechanism
from linkd.topology import Status, assembly_plan
from linkd.validator import validate_mechanism


def joint_paths(mech: Mechanism, angles: int | np.ndarray) -> np.ndarray:
    """(N, T, 2) joint positions at the crank angles (a count T, or radians from the assembly pose);
    where the crank is cut in two and driven (mechanism.json's `drive`), its points after them.

    Raises ValueError with the validator's reason when the mechanism is not a working one.
    """
    status, _ = validate_mechanism(mech)
    if status != Status.VALID:
        raise ValueError(status.reason)
    pivot, tip = mech.motor
    order = [pivot, tip, *(k for k in range(mech.n_nodes) if k not in (pivot, tip))]
    batch = LinkageBatch.from_mechanisms([mech])
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    angles = angles if isinstance(angles, int) else np.asarray(angles, dtype=np.float64)
    motion = trace(batch.positions, plan, angles)
    paths = np.empty((mech.n_nodes, motion.x.shape[-1], 2))
    paths[order] = np.stack([motion.x[0], motion.y[0]], -1)
    if "drive" not in mech.extra:
        return paths
    turns = 2 * np.pi * np.arange(angles) / angles if isinstance(angles, int) else angles
    return np.concatenate([paths, drive_paths(mech.extra["drive"], turns)])


def drive_paths(drive: dict, angles: np.ndarray) -> np.ndarray:
    """(K, T, 2) paths of the points of a crank cut in two and its drive (mechanism.json's
    `drive`, joints N, N + 1, ...): each turns with the crank about its centre."""
    points, centres = np.array(drive["points"], float), np.array(drive["centres"], float)
    c, s = np.cos(angles), np.sin(angles)
    x, y = (points - centres).T[:, :, None]
    return centres[:, None] + np.stack([c * x - s * y, s * x + c * y], -1)


def all_positions(mech: Mechanism) -> np.ndarray:
    """The joints in the assembly pose, a drive's points after them."""
    extra = mech.extra.get("drive", {}).get("points", [])
    return np.concatenate([mech.positions, np.reshape(np.array(extra, float), (-1, 2))])


def rigid_parts(mech: Mechanism) -> list[tuple[int, ...]]:
    """Joint sets of the rigid parts: the ground, ternary (or larger) plates, binary bars.

    Links of a triangle are one plate, and plates sharing a link are one part. The fixed joints
    form the ground, which comes first; links between two fixed joints belong to it.
    """
    adjacency = mech.adjacency()
    groups: list[set[int]] = []
    for i, j in mech.links:
        if mech.fixed[i] and mech.fixed[j]:
            continue
        third = {int(k) for k in np.flatnonzero(adjacency[i] & adjacency[j])}
        group = {i, j} | third
        for other in [g for g in groups if len(g & group) >= 2]:
            groups.remove(other)
            group |= other
        groups.append(group)
    ground = tuple(int(k) for k in np.flatnonzero(mech.fixed))
    return [ground, *(tuple(sorted(g)) for g in groups)]
