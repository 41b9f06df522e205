"""The dynamic run: the motor servo turns the crank once in simulation, with the model's options.

The control ramps from 0 to 2*pi over RAMP_S seconds, then holds for SETTLE_S. After every step
the positions are brought up to date (`mj_kinematics`) and recorded; loop violation and path
error are computed afterwards for all steps at once. The run stops at the first contact between
parts: from there on it no longer tests the design (the collisions check names the pair).
Contacts are looked for at a step's new positions (`mj_collision`), not in each of the
integrator's four stages, every CONTACT_EVERY_S of simulated time: until the first contact no
contact force acts either way, and mesh collisions were five sixths of a step's time.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from linkd.mechanism import UNITS_IN_METRES, Mechanism

from .analytic import joint_paths
from .checks import (
    CRANK_TOL,
    DYNAMIC_PATH_RTOL,
    END_EFFECTOR,
    LOOP_RTOL,
    MOTOR,
    RAMP_S,
    SETTLE_S,
    Check,
    capture_warnings,
    rms_radius,
    verdict,
)
from .pose import CRANK, Connects

CONTACT_EVERY_S = 2.5e-4  # simulated time between looks for contacts: every step at the export's
# default step, and as often on a model with a finer one (a sixteenth: 80,000 steps a run)


def simulate(model: Any) -> dict[str, Any]:
    """Run the ramp; per step the crank angle, end-effector and anchor xy, contact count."""
    data = mujoco.MjData(model)
    obj = mujoco.mjtObj
    crank = int(model.jnt_qposadr[mujoco.mj_name2id(model, obj.mjOBJ_JOINT, CRANK)])
    motor = mujoco.mj_name2id(model, obj.mjOBJ_ACTUATOR, MOTOR)
    ee = mujoco.mj_name2id(model, obj.mjOBJ_SITE, END_EFFECTOR)
    connects = Connects.of(model, data)
    steps = round((RAMP_S + SETTLE_S) / model.opt.timestep)
    angle, ends, xpos, xmat = [], [], [], []  # the anchors' bodies' poses, placed at the end
    first_contact = None
    finite = True
    flags = model.opt.disableflags
    stepping = flags | mujoco.mjtDisableBit.mjDSBL_CONTACT.value
    every = max(1, round(CONTACT_EVERY_S / model.opt.timestep))
    with capture_warnings() as messages:
        try:
            for step in range(steps):
                data.ctrl[motor] = 2 * np.pi * min(data.time / RAMP_S, 1.0)
                model.opt.disableflags = stepping
                mujoco.mj_step(model, data)
                model.opt.disableflags = flags
                if not (np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all()):
                    finite = False
                    break
                mujoco.mj_kinematics(model, data)
                if step % every == every - 1:
                    mujoco.mj_collision(model, data)
                if data.ncon:  # parts touch: the run no longer tests the design; stop here
                    pair = data.contact.geom[0]
                    first_contact = (int(pair[0]), int(pair[1]),
                                     data.qpos[crank] - model.qpos0[crank])  # fmt: skip
                    break
                angle.append(data.qpos[crank] - model.qpos0[crank])
                ends.append(data.site_xpos[ee, :2].copy())
                xpos.append(data.xpos[connects.bodies])
                xmat.append(data.xmat[connects.bodies])
        finally:
            model.opt.disableflags = flags
    counted = sum(int(w.number) for w in data.warning)
    shape = (len(angle), *connects.bodies.shape)
    anchors = connects.placed(np.reshape(xpos, (*shape, 3)), np.reshape(xmat, (*shape, 9)))
    return {
        "angle": np.array(angle),
        "end": np.array(ends).reshape(-1, 2),
        "anchors": anchors[..., :2],
        "first_contact": first_contact,
        "finite": finite,
        "warnings": messages + ([f"{counted} warning counts in mjData"] if counted else []),
        "seconds": steps * model.opt.timestep,
    }


def check_dynamics(model: Any, mech: Mechanism) -> tuple[Check, tuple | None]:
    """Drive the motor through one revolution.

    Returns the check and the run's first contact (geom ids and crank angle), if any.
    """
    unit = UNITS_IN_METRES[mech.units]
    threshold = (
        f"crank 2*pi +- {CRANK_TOL:g} rad; loops <= {LOOP_RTOL:g} x shortest link; "
        f"path <= {DYNAMIC_PATH_RTOL:g} x RMS radius; no NaN or warning"
    )
    run = simulate(model)
    problems = [f"MuJoCo warning: {w}" for w in run["warnings"]]
    if run["first_contact"] is not None:
        angle = np.degrees(run["first_contact"][2])
        problems.append(f"stopped at a contact at crank angle {angle:.1f} deg (see collisions)")
    if not run["finite"]:
        problems.append(f"NaN or inf after {len(run['angle'])} steps")
    if len(run["angle"]) == 0:
        return verdict("dynamics", False, None, threshold, "; ".join(problems)), run[
            "first_contact"
        ]
    shortest = float(mech.link_lengths().min()) * unit
    violation = np.linalg.norm(run["anchors"][:, :, 0] - run["anchors"][:, :, 1], axis=-1)
    loop = float(violation.max(initial=0.0) / shortest)
    try:
        target = joint_paths(mech, run["angle"])[mech.end_effector] * unit
        radius = rms_radius(joint_paths(mech, 200)[mech.end_effector] * unit)
        path = float(np.linalg.norm(run["end"] - target, axis=1).max() / radius)
    except ValueError as exc:
        problems.append(f"mechanism.json: invalid: {exc}")
        path = float("nan")
    final = float(run["angle"][-1])
    if abs(final - 2 * np.pi) > CRANK_TOL:
        problems.append(f"the crank turned {np.degrees(final):.2f} deg, not 360")
    if loop > LOOP_RTOL:
        problems.append(f"loop violation {loop:.3g} x shortest link")
    if not path <= DYNAMIC_PATH_RTOL:  # NaN too: a path that cannot be compared fails
        problems.append(f"path error {path:.3g} x RMS radius")
    summary = (
        f"crank turned {np.degrees(final):.3f} deg in {run['seconds']:.2f} s; loop violation "
        f"{loop:.3g} x shortest link; path error {path:.3g} x RMS radius"
    )
    detail = "; ".join(problems) if problems else summary
    check = verdict("dynamics", not problems, loop, threshold, detail,
                    crank_turn_rad=final, loop_violation=loop, path_error=path,
                    steps=len(run["angle"]), timestep_s=float(model.opt.timestep))  # fmt: skip
    return check, run["first_contact"]
