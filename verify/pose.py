"""Poses of an exported mechanism: hold the crank, solve the other joints from the loop closures.

The exported MJCF is a spanning tree of hinges whose remaining loops are closed by `connect`
equalities. With the `crank` hinge held at an angle (relative to the assembly pose, the model's
`qpos0`), the other hinges follow from the equality residuals alone: Gauss-Newton steps on the
residuals (minimum-norm least squares, Levenberg-Marquardt damping when a step does not pay),
warm-started along a sweep with the tangent of the solution curve so each angle needs one or two
iterations and the solver never jumps to the other assembly branch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

CRANK = "crank"
TOL = 1e-12  # metres: loop-closure residual a solved pose must reach
ROUNDING = 64 * np.finfo(np.float64).eps  # of the anchors' distance from the world origin:
# the least residual their rounding allows, which sets the tolerance far from the origin
MAX_ITER = 50
MAX_STEP = 2 * np.pi / 400  # radians: largest crank step of a sweep before it is subdivided


def crank_dof(model: Any) -> int:
    """Index in qpos (= qvel for a model of hinges) of the `crank` hinge."""
    jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, CRANK)
    if jid < 0:
        raise ValueError(f"the model has no joint named {CRANK!r}")
    if model.nq != model.nv:
        raise ValueError("pose solving needs a model of hinges and slides only (nq == nv)")
    return int(model.jnt_qposadr[jid])


def active_connects(model: Any, data: Any) -> np.ndarray:
    """Ids of the `connect` equalities active in `data`."""
    ids = np.flatnonzero(model.eq_type == mujoco.mjtEq.mjEQ_CONNECT)
    return ids[np.asarray(data.eq_active, dtype=bool)[ids]]


@dataclass
class Connects:
    """Connect equalities as pairs of body-fixed anchor points (site- or body-based alike)."""

    eqs: np.ndarray  # (E,) equality ids
    bodies: np.ndarray  # (E, 2) the body carrying each anchor
    local: np.ndarray  # (E, 2, 3) each anchor in its body's frame

    @classmethod
    def of(cls, model: Any, data: Any, eqs: np.ndarray | None = None) -> Connects:
        """The active connects of `data` (or the equalities `eqs`)."""
        eqs = active_connects(model, data) if eqs is None else np.asarray(eqs, dtype=int)
        objs = np.stack([model.eq_obj1id[eqs], model.eq_obj2id[eqs]], -1).reshape(-1, 2)
        on_site = (model.eq_objtype[eqs] == mujoco.mjtObj.mjOBJ_SITE)[:, None]
        bodies = np.where(on_site, model.site_bodyid[objs], objs)
        local = model.eq_data[eqs, :6].reshape(-1, 2, 3).copy()
        local[on_site[:, 0]] = model.site_pos[objs[on_site[:, 0]]]
        return cls(eqs, bodies, local)

    def points(self, data: Any) -> np.ndarray:
        """(E, 2, 3) world positions of both anchors of each equality."""
        return self.placed(data.xpos[self.bodies], data.xmat[self.bodies])

    def placed(self, xpos: np.ndarray, xmat: np.ndarray) -> np.ndarray:
        """(..., E, 2, 3) the anchors in world coordinates for the anchor bodies' (..., E, 2, 3)
        positions and (..., E, 2, 9) orientations: many recorded states at once."""
        rotation = xmat.reshape(*xmat.shape[:-1], 3, 3)
        return xpos + np.einsum("...ij,...j->...i", rotation, self.local)


def loop_closure(
    model: Any, data: Any, qpos: np.ndarray, connects: Connects | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Residual (3E,) and Jacobian (3E, nv) of the connect equalities at `qpos`.

    The residual of each equality is anchor 1 minus anchor 2 in world coordinates (metres),
    as in MuJoCo's own constraint rows. connects: default the active ones.
    """
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    connects = Connects.of(model, data) if connects is None else connects
    points = connects.points(data)
    jacobian = np.zeros((points.size // 3, 3, model.nv))
    for row, body, point in zip(jacobian, connects.bodies.flat, points.reshape(-1, 3)):
        mujoco.mj_jac(model, data, row, None, point, int(body))
    jacobian = jacobian.reshape(-1, 2, 3, model.nv)
    residual = (points[:, 0] - points[:, 1]).reshape(-1)
    return residual, (jacobian[:, 0] - jacobian[:, 1]).reshape(-1, model.nv)


def pin_points(model: Any, data: Any) -> dict[int, np.ndarray]:
    """For each weld body, the xy of the pins it carries or turns on (at the current pose)."""
    weld = np.asarray(model.body_weldid)
    points: dict[int, list[np.ndarray]] = {}
    for j in range(model.njnt):
        body = int(model.jnt_bodyid[j])
        for owner in {int(weld[body]), int(weld[model.body_parentid[body]])}:
            points.setdefault(owner, []).append(data.xanchor[j, :2])
    connects = Connects.of(model, data)
    for body, point in zip(connects.bodies.reshape(-1), connects.points(data).reshape(-1, 3)):
        points.setdefault(int(weld[body]), []).append(point[:2])
    return {w: np.array(p) for w, p in points.items()}


def _newton(
    model: Any, data: Any, qpos: np.ndarray, free: np.ndarray, tol: float, connects: Connects
) -> tuple[np.ndarray, float, np.ndarray, float]:
    """Drive the loop residual to `tol` (or what rounding allows, far from the origin) over the
    `free` coordinates.

    Returns the pose, its residual norm, its loop-closure Jacobian and the tolerance used.
    """
    residual, jacobian = loop_closure(model, data, qpos, connects)
    tol = max(tol, ROUNDING * float(np.abs(connects.points(data)).max(initial=0.0)))
    error = float(np.linalg.norm(residual))
    scale = float((jacobian[:, free] ** 2).sum())  # typical size of J'J
    damping, posed = 0.0, True  # posed: `data` holds the kinematics of `qpos`
    for _ in range(MAX_ITER):
        if error <= tol:
            break
        jf = jacobian[:, free]
        if damping == 0.0:
            step = np.linalg.lstsq(jf, -residual, rcond=None)[0]
        else:
            lhs = jf.T @ jf + damping * np.eye(jf.shape[1])
            step = np.linalg.solve(lhs, -jf.T @ residual)
        trial = qpos.copy()
        trial[free] += step
        new_residual, new_jacobian = loop_closure(model, data, trial, connects)
        new_error = float(np.linalg.norm(new_residual))
        if new_error < error:  # accept; trust the Gauss-Newton step more
            qpos, residual, jacobian, error = trial, new_residual, new_jacobian, new_error
            damping = damping / 10 if damping > 1e-9 * scale else 0.0
        else:  # reject; damp towards gradient descent
            damping = max(10 * damping, 1e-6 * scale)
        posed = trial is qpos
    if not posed:
        loop_closure(model, data, qpos, connects)
    return qpos, error, jacobian, tol


def solve_pose(
    model: Any,
    data: Any,
    crank_angle: float,
    qpos0: np.ndarray | None = None,
    tol: float = TOL,
) -> np.ndarray:
    """The pose (nq,) with the crank at `crank_angle` radians from the assembly pose.

    qpos0: starting guess for the other joints (default the model's assembly pose); pass the
    previous pose of a sweep. Raises ValueError when the loops cannot be closed to `tol`.
    Leaves `data` at the returned pose (kinematics computed).
    """
    connects = Connects.of(model, data)
    return _solve(model, data, crank_dof(model), crank_angle, qpos0, tol, connects)[0]


def _solve(
    model: Any,
    data: Any,
    crank: int,
    angle: float,
    guess: np.ndarray | None,
    tol: float,
    connects: Connects,
) -> tuple[np.ndarray, np.ndarray]:
    """solve_pose, also returning the loop-closure Jacobian at the solution."""
    start = np.array(model.qpos0 if guess is None else guess, dtype=np.float64)
    start[crank] = model.qpos0[crank] + angle
    free = np.arange(model.nv) != crank
    qpos, error, jacobian, tol = _newton(model, data, start, free, tol, connects)
    if not error <= tol:
        raise ValueError(
            f"loops do not close at crank angle {angle:.6g} rad (residual {error:.3g} m)"
        )
    return qpos, jacobian


def _tangent(jacobian: np.ndarray, crank: int) -> np.ndarray:
    """dq/d(crank angle) that keeps the loops closed, to first order."""
    free = np.arange(jacobian.shape[1]) != crank
    tangent = np.zeros(jacobian.shape[1])
    tangent[crank] = 1.0
    tangent[free] = -np.linalg.lstsq(jacobian[:, free], jacobian[:, crank], rcond=None)[0]
    return tangent


def solve_sweep(
    model: Any,
    data: Any,
    angles: np.ndarray,
    tol: float = TOL,
    max_step: float = MAX_STEP,
) -> np.ndarray:
    """Poses (T, nq) at increasing crank `angles` (radians from the assembly pose).

    Continues from the assembly pose through every angle in order, inserting intermediate
    angles where consecutive ones are more than `max_step` apart, predicting each pose from
    the previous one along the tangent. Raises ValueError at the first angle that will not close.
    """
    crank = crank_dof(model)
    angles = np.asarray(angles, dtype=np.float64)
    connects = Connects.of(model, data)
    qpos, jacobian = _solve(model, data, crank, 0.0, None, tol, connects)
    current = 0.0
    poses = np.zeros((len(angles), model.nq))
    for k, target in enumerate(angles):
        substeps = max(1, int(np.ceil(abs(target - current) / max_step)))
        for angle in np.linspace(current, target, substeps + 1)[1:]:
            guess = qpos + _tangent(jacobian, crank) * (angle - current)
            qpos, jacobian = _solve(model, data, crank, angle, guess, tol, connects)
            current = angle
        poses[k] = qpos
    return poses
