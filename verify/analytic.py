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
    """(N, T, 2) joint positions at the crank angles (a count T, or radians from the assembly pose).

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
    return paths


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
