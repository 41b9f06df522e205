"""The physics checks of `linkd verify`: an exported MuJoCo model against its mechanism.json.

Each check returns a `Check` with one headline figure and the threshold it is held to:

- load: mechanism.xml compiles with no MuJoCo warning; the contract's names are present (hinge
  `crank`, position actuator `motor` on it with unit gear and no control limits, site
  `end_effector`); every joint is a hinge about z; every active equality is a `connect`;
  contacts and constraints are enabled; every moving part's own geoms hold its pins
  (`holding`).
- mobility: at N_ANGLES crank angles (the loops solved with the crank held, `pose.solve_sweep`),
  the loop-closure Jacobian J (3 rows per connect, one column per dof) has nv - rank(J) = 1 and
  rank(J without the crank column) = nv - 1 (crank held, the rest is locked). A singular value
  counts as zero below RANK_RTOL times the largest. Figure: the least singular value of the free
  columns over the cycle divided by the mechanism's size in metres (0 = a toggle pose). A pose
  where the loops cannot be closed means the mechanism locks there.
- kinematics: at those poses the `end_effector` site matches mechanism.json's analytic path
  (metres = units x UNITS_IN_METRES) within PATH_RTOL of the path's RMS radius about its
  centroid, and every hinge and connect anchor sits on a joint of mechanism.json within
  PATH_RTOL of the mechanism's size.
- dynamics: the `motor` control ramps from 0 to 2*pi over RAMP_S seconds and holds for SETTLE_S;
  the model's own integrator and time step. The crank ends within CRANK_TOL radians of 2*pi, the
  loop violation stays under LOOP_RTOL of the shortest link, the end effector stays within
  DYNAMIC_PATH_RTOL of the path's RMS radius from the analytic path at the crank's actual angle,
  no value turns NaN, MuJoCo raises no warning and no parts touch (the run stops at a contact).
- collisions: at the solved poses, MuJoCo's collision detection finds no contact and the exact
  distance (`mj_geomDistance`) between every pair of geoms MuJoCo would collide is positive; a
  pair the model keeps out of collision (contype/conaffinity, `exclude`) must be a pin in the
  hole of a part it joins. Contacts in the dynamic run count too. Figure: the least clearance.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from linkd.mechanism import UNITS_IN_METRES, Mechanism

from .analytic import joint_paths
from .holding import unheld_pins
from .pose import CRANK, Connects, loop_closure

N_ANGLES = 200  # crank angles 2*pi*k/N of the kinematic checks
RANK_RTOL = 1e-9  # singular values below this fraction of the largest count as zero
PATH_RTOL = 1e-6  # kinematic path error, of the path's RMS radius
RAMP_S, SETTLE_S = 1.0, 0.25  # s: control ramp 0 -> 2*pi (one revolution a second), then hold
CRANK_TOL = 1e-2  # rad: the crank's final angle from 2*pi
LOOP_RTOL = 1e-6  # dynamic loop violation, of the shortest link
DYNAMIC_PATH_RTOL = 1e-5  # dynamic path error, of the path's RMS radius
MOTOR, END_EFFECTOR = "motor", "end_effector"


@dataclass
class Check:
    """One verdict: `status` is pass, fail or skip (a check that could not run fails the whole)."""

    name: str
    status: str
    figure: float | None
    threshold: str
    detail: str
    figures: dict[str, Any] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return self.status == "pass"


def verdict(name: str, ok: bool, figure: float | None, threshold: str, detail: str, **figures: Any):
    return Check(name, "pass" if ok else "fail", figure, threshold, detail, figures)


def skipped(name: str, threshold: str, reason: str) -> Check:
    return Check(name, "skip", None, threshold, reason)


@contextmanager
def capture_warnings() -> Iterator[list[str]]:
    """Collect MuJoCo's warnings (instead of printing them and writing MUJOCO_LOG.TXT)."""
    messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)
    try:
        yield messages
    finally:
        mujoco.set_mju_user_warning(previous)


def _id(model: Any, kind: Any, name: str) -> int:
    return mujoco.mj_name2id(model, kind, name)


# ---- load --------------------------------------------------------------------------------------


def check_load(xml_path: str) -> tuple[Check, Any]:
    """Compile the model, watching for warnings; check the contract's names. Returns the model."""
    threshold = "no warning; contract names present"
    with capture_warnings() as messages:
        try:
            model = mujoco.MjModel.from_xml_path(xml_path)
        except ValueError as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else "unknown error"
            return verdict("load", False, None, threshold, f"does not compile: {first}"), None
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
    problems = [f"MuJoCo warning: {m}" for m in messages] + contract_problems(model, data)
    problems += unheld_pins(model, data)
    detail = "; ".join(problems) if problems else f"{model.nbody - 1} bodies, nv {model.nv}"
    return verdict("load", not problems, float(len(problems)), threshold, detail), model


def contract_problems(model: Any, data: Any) -> list[str]:
    """What the model lacks of CONTRACT section 3 (names, joint kinds, actuator, equalities)."""
    obj = mujoco.mjtObj
    problems = []
    crank = _id(model, obj.mjOBJ_JOINT, CRANK)
    if crank < 0:
        problems.append(f"no joint named {CRANK!r}")
    kinds = np.asarray(model.jnt_type)
    if (kinds != mujoco.mjtJoint.mjJNT_HINGE).any():
        problems.append(
            f"{int((kinds != mujoco.mjtJoint.mjJNT_HINGE).sum())} joints are not hinges"
        )
    tilted = np.abs(np.abs(data.xaxis[:, 2]) - 1) > 1e-9
    if tilted.any():
        problems.append(f"{int(tilted.sum())} hinge axes are not along z")
    motor = _id(model, obj.mjOBJ_ACTUATOR, MOTOR)
    if motor < 0:
        problems.append(f"no actuator named {MOTOR!r}")
    else:
        gain, bias = model.actuator_gainprm[motor], model.actuator_biasprm[motor]
        position = (
            model.actuator_gaintype[motor] == mujoco.mjtGain.mjGAIN_FIXED
            and model.actuator_biastype[motor] == mujoco.mjtBias.mjBIAS_AFFINE
            and gain[0] > 0
            and bias[0] == 0
            and bias[1] == -gain[0]
        )
        if not position:
            problems.append(f"actuator {MOTOR!r} is not a position servo")
        on_crank = (
            model.actuator_trntype[motor] == mujoco.mjtTrn.mjTRN_JOINT
            and model.actuator_trnid[motor, 0] == crank
        )
        if not on_crank:
            problems.append(f"actuator {MOTOR!r} does not drive joint {CRANK!r}")
        if model.actuator_gear[motor, 0] != 1 or model.actuator_ctrllimited[motor]:
            problems.append(f"actuator {MOTOR!r} needs gear 1 and unlimited control")
    if _id(model, obj.mjOBJ_SITE, END_EFFECTOR) < 0:
        problems.append(f"no site named {END_EFFECTOR!r}")
    active = np.asarray(data.eq_active, dtype=bool)
    others = active & (model.eq_type != mujoco.mjtEq.mjEQ_CONNECT)
    if others.any():
        problems.append(f"{int(others.sum())} active equalities are not connect")
    off = mujoco.mjtDisableBit
    for flag, what in [(off.mjDSBL_CONTACT, "contacts"), (off.mjDSBL_CONSTRAINT, "constraints"),
                       (off.mjDSBL_EQUALITY, "equalities")]:  # fmt: skip
        if model.opt.disableflags & flag:
            problems.append(f"{what} are disabled")
    return problems


# ---- mobility and kinematics -------------------------------------------------------------------


def pose_quantities(model: Any, poses: np.ndarray) -> dict[str, np.ndarray]:
    """Loop-closure Jacobians, end-effector and anchor positions at each pose (metres)."""
    data = mujoco.MjData(model)
    ee = _id(model, mujoco.mjtObj.mjOBJ_SITE, END_EFFECTOR)
    connects = Connects.of(model, data)
    jacobians, ends, anchors = [], [], []
    for qpos in poses:
        _, jacobian = loop_closure(model, data, qpos, connects)
        jacobians.append(jacobian)
        ends.append(data.site_xpos[ee, :2].copy())
        pins = connects.points(data)[..., :2].reshape(-1, 2)
        anchors.append(np.vstack([data.xanchor[:, :2], pins]))
    return {"jacobian": np.array(jacobians), "end": np.array(ends), "anchors": np.array(anchors)}


def check_mobility(
    model: Any, jacobians: np.ndarray | None, angles: np.ndarray, size: float, lock: str | None
) -> Check:
    """One degree of freedom at every solved pose; the crank held locks the rest.

    jacobians: (T, rows, nv) at the crank `angles`; lock: why the poses could not be solved.
    """
    threshold = f"nv - rank = 1, crank held rank = nv - 1 (rtol {RANK_RTOL:g})"
    if lock is not None:
        return verdict("mobility", False, 0.0, threshold, f"the mechanism locks: {lock}")
    crank = int(model.jnt_dofadr[_id(model, mujoco.mjtObj.mjOBJ_JOINT, CRANK)])
    free = np.arange(model.nv) != crank
    if jacobians.shape[1] == 0:  # no loops (a lone crank): one zero row keeps the ranks right
        jacobians = np.zeros((len(jacobians), 1, model.nv))
    full = np.linalg.svd(jacobians, compute_uv=False)  # (T, min(rows, nv))
    held = np.linalg.svd(jacobians[:, :, free], compute_uv=False)
    cutoff = RANK_RTOL * full[:, :1]
    dof = model.nv - (full > cutoff).sum(1)
    held_rank = (held > cutoff).sum(1)
    if model.nv == 1:  # nothing but the crank: nothing can reach a toggle
        smallest = np.full(len(held), np.inf)
    elif held.shape[1] == model.nv - 1:
        smallest = held[:, -1]
    else:
        smallest = np.zeros(len(held))
    toggle = float(smallest.min() / size)
    bad = np.flatnonzero((dof != 1) | (held_rank != model.nv - 1))
    if len(bad):
        k = int(bad[0])
        angle = np.degrees(angles[k])
        detail = f"{int(dof[k])} degrees of freedom, crank-held rank {int(held_rank[k])} of "
        detail += f"{model.nv - 1} at crank angle {angle:.1f} deg"
        return verdict("mobility", False, toggle, threshold, detail, poses=len(jacobians))
    detail = f"1 dof at all {len(jacobians)} poses; least free singular value {toggle:.3g} x size"
    return verdict("mobility", True, toggle, threshold, detail, poses=len(jacobians))


def rms_radius(path: np.ndarray) -> float:
    return float(np.sqrt(((path - path.mean(0)) ** 2).sum(1).mean()))


def check_kinematics(
    mech: Mechanism, quantities: dict[str, np.ndarray] | None, angles: np.ndarray
) -> Check:
    """The end-effector site and every pin follow mechanism.json's analytic motion."""
    threshold = f"<= {PATH_RTOL:g} x path RMS radius"
    unit = UNITS_IN_METRES[mech.units]
    try:
        paths = joint_paths(mech, angles) * unit  # (N, T, 2) metres
    except ValueError as exc:
        return verdict("kinematics", False, None, threshold, f"mechanism.json: invalid: {exc}")
    if quantities is None:
        return skipped("kinematics", threshold, "no solved poses (see mobility)")
    target = paths[mech.end_effector]
    radius = rms_radius(target)
    end_error = np.linalg.norm(quantities["end"] - target, axis=1)
    gaps = np.linalg.norm(
        quantities["anchors"][:, :, None] - paths.transpose(1, 0, 2)[:, None], axis=-1
    )
    pin_error = gaps.min(2).max(1)  # (T,) worst anchor's distance to its nearest joint
    size = mech.scale * unit
    worst = float(end_error.max() / radius)
    ok = worst <= PATH_RTOL and pin_error.max() <= PATH_RTOL * size
    k = int(np.argmax(end_error)) if worst > PATH_RTOL else int(np.argmax(pin_error))
    detail = (
        f"end effector off by {end_error.max():.3g} m (path RMS radius {radius:.4g} m); "
        f"pins off joints by {pin_error.max():.3g} m"
    )
    if not ok:
        detail += f"; worst at crank angle {np.degrees(angles[k]):.1f} deg"
    return verdict("kinematics", ok, worst, threshold, detail,
                   end_error_m=float(end_error.max()), pin_error_m=float(pin_error.max()),
                   path_rms_radius_m=radius)  # fmt: skip
