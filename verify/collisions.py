"""Collision-freedom over the revolution: MuJoCo's contacts and exact part-to-part clearances.

A pair of geoms is checked when MuJoCo itself would collide it (contype/conaffinity, `exclude`
lists, weld and parent filters, as in its broad phase). A pair the model leaves out must be a pin
in the hole of a part it joins: a cylinder centred on a pin point (hinge or loop-closure anchor)
of the other part; any other exclusion would hide a collision, so it fails the check.
"""

from __future__ import annotations

from itertools import combinations
from typing import Any

import mujoco
import numpy as np

from .checks import Check, verdict
from .pose import pin_points

PIN_RTOL = 1e-6  # a cylinder is on a pin point within this fraction of the mechanism's size


def geom_name(model: Any, geom: int) -> str:
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, geom)
    body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(model.geom_bodyid[geom]))
    return name or f"geom {geom} of {body or 'world'}"


def mujoco_collides(model: Any, g1: int, g2: int, excluded: set[int]) -> bool:
    """Would MuJoCo's collision detection consider this geom pair? (Explicit pairs aside.)

    excluded: the model's body-pair exclusion signatures, (low body id << 16) + high body id.
    """
    b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
    w1, w2 = int(model.body_weldid[b1]), int(model.body_weldid[b2])
    p1 = int(model.body_weldid[model.body_parentid[w1]])
    p2 = int(model.body_weldid[model.body_parentid[w2]])
    if w1 == w2:
        return False
    filter_parent = not model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_FILTERPARENT
    if filter_parent and w1 and w2 and (w1 == p2 or w2 == p1):
        return False
    lo, hi = min(b1, b2), max(b1, b2)
    if (lo << 16) + hi in excluded:
        return False
    c1, a1 = model.geom_contype[g1], model.geom_conaffinity[g1]
    c2, a2 = model.geom_contype[g2], model.geom_conaffinity[g2]
    return bool((c1 & a2) or (c2 & a1))


def classify_pairs(model: Any, size: float) -> tuple[list[tuple[int, int]], list[str]]:
    """Geom pairs MuJoCo checks, and the left-out pairs that are not a pin in its hole."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    weld = np.asarray(model.body_weldid)
    pins = pin_points(model, data)
    explicit = {tuple(sorted(p)) for p in zip(model.pair_geom1, model.pair_geom2)}
    excluded = set(model.exclude_signature.tolist())
    checked, suspicious = [], []
    for g1, g2 in combinations(range(model.ngeom), 2):
        w1, w2 = weld[model.geom_bodyid[g1]], weld[model.geom_bodyid[g2]]
        if w1 == w2:
            continue  # one rigid body (the ground included): its geoms never move apart
        if (g1, g2) in explicit or mujoco_collides(model, g1, g2, excluded):
            checked.append((g1, g2))
        elif not _pin_in_hole(model, data, g1, w2, pins, size) and not _pin_in_hole(
            model, data, g2, w1, pins, size
        ):
            suspicious.append(f"{geom_name(model, g1)} / {geom_name(model, g2)}")
    return checked, suspicious


def _pin_in_hole(model: Any, data: Any, pin: int, other: int, pins: dict, size: float) -> bool:
    """Is geom `pin` a cylinder standing on a pin point of weld body `other`?"""
    if model.geom_type[pin] != mujoco.mjtGeom.mjGEOM_CYLINDER or other not in pins:
        return False
    centre = data.geom_xpos[pin, :2]
    return bool(np.linalg.norm(pins[other] - centre, axis=1).min() <= PIN_RTOL * size)


def box_distances(model: Any, data: Any, g1: np.ndarray, g2: np.ndarray) -> np.ndarray:
    """Distances between the world-aligned boxes round the geoms of each pair at the current
    pose: no pair is nearer, so exact distances are only needed where a box comes near."""
    rotation = data.geom_xmat.reshape(-1, 3, 3)
    centre = data.geom_xpos + np.einsum("gij,gj->gi", rotation, model.geom_aabb[:, :3])
    half = np.einsum("gij,gj->gi", np.abs(rotation), model.geom_aabb[:, 3:])
    gap = np.abs(centre[g1] - centre[g2]) - half[g1] - half[g2]
    return np.linalg.norm(np.maximum(gap, 0.0), axis=-1)


def check_collisions(
    model: Any, poses: np.ndarray | None, size: float, dynamic_contact: tuple | None
) -> Check:
    """No contact and positive clearance between parts at every solved pose. The least
    clearance is exact: pairs are measured nearest box first, until no box comes nearer."""
    threshold = "no contact; least clearance > 0"
    if poses is None:
        return Check("collisions", "skip", None, threshold, "no solved poses (see mobility)")
    checked, suspicious = classify_pairs(model, size)
    data = mujoco.MjData(model)
    g1, g2 = (np.array([p[k] for p in checked], int) for k in (0, 1))
    crank_angles = np.arange(len(poses)) * (2 * np.pi / len(poses))
    bounds, first_contact = np.zeros((len(poses), len(checked))), None
    for t, (angle, qpos) in enumerate(zip(crank_angles, poses)):
        data.qpos[:] = qpos
        mujoco.mj_fwdPosition(model, data)
        if data.ncon and first_contact is None:
            first_contact = (*data.contact.geom[0], angle)
        bounds[t] = box_distances(model, data, g1, g2)
    least, where, posed = np.inf, None, None
    for t, k in zip(*np.unravel_index(np.argsort(bounds, axis=None, kind="stable"), bounds.shape)):
        if 0 < bounds[t, k] >= least:
            break  # no pair left can come nearer (boxes that meet may hold parts that cross)
        if t != posed:
            data.qpos[:] = poses[t]
            mujoco.mj_kinematics(model, data)
            posed = t
        distance = mujoco.mj_geomDistance(model, data, int(g1[k]), int(g2[k]), size, None)
        if distance < least:
            least, where = distance, (g1[k], g2[k], crank_angles[t])
    problems = [f"excluded from contact but not a pin in its hole: {p}" for p in suspicious]
    for source, contact in (("pose", first_contact), ("dynamic run", dynamic_contact)):
        if contact is not None:
            a, b, angle = contact
            problems.append(
                f"contact {geom_name(model, a)} / {geom_name(model, b)} at crank angle "
                f"{np.degrees(angle):.1f} deg ({source})"
            )
    if where is not None and least <= 0 and first_contact is None:
        a, b, angle = where
        problems.append(
            f"{geom_name(model, a)} / {geom_name(model, b)} touch at crank angle "
            f"{np.degrees(angle):.1f} deg"
        )
    if where is None:
        summary = "no pair of moving parts to check"
    else:
        a, b, angle = where
        summary = (
            f"least clearance {least:.3g} m ({geom_name(model, a)} / {geom_name(model, b)} at "
            f"{np.degrees(angle):.1f} deg) over {len(checked)} pairs x {len(poses)} poses"
        )
    detail = "; ".join([*problems, summary]) if problems else summary
    figure = None if where is None else float(least)
    return verdict("collisions", not problems, figure, threshold, detail,
                   pairs=len(checked), excluded_suspicious=len(suspicious))  # fmt: skip
