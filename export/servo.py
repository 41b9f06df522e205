"""The crank's position servo, sized from the model's own inertia along the analytic motion."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from linkd.mechanism import Mechanism

from .parts import hinge_angles

if TYPE_CHECKING:
    import mujoco

    from .drive import Drive

SERVO_HZ = 10.0  # natural frequency of the crank servo at the crank's largest inertia


@dataclass(frozen=True)
class Servo:
    """The crank's position servo and the motor's rotor inertia (armature) on the crank hinge."""

    kp: float  # N m / rad
    kv: float  # N m s / rad
    armature: float  # kg m^2


UNSIZED = Servo(1.0, 0.1, 0.0)  # the servo of a model compiled only to be weighed


def qpos_at(model, mech: Mechanism, angles: np.ndarray, drive: Drive | None = None) -> np.ndarray:
    """(T, nq) joint positions of the exported model at crank angles (analytic kinematics), the
    `drive`'s hinges too where the crank is cut in two."""
    qpos = np.tile(model.qpos0, (len(angles), 1))
    turns = hinge_angles(mech, angles) | (drive.hinge_angles(angles) if drive else {})
    for name, values in turns.items():
        qpos[:, model.joint(name).qposadr[0]] = values
    return qpos


def servo_gains(
    model: mujoco.MjModel, mech: Mechanism, drive: Drive | None = None, n_angles: int = 64
) -> Servo:
    """Crank servo and rotor inertia from the largest inertia the crank drives in a revolution.

    That inertia is max v' M v over the cycle, v being the joint velocities per unit crank
    speed (central differences of the analytic pose). A rotor of the same inertia keeps the
    crank hinge from being the lightest thing in the model, whose own mode under the servo
    would otherwise be too fast for an explicit integrator; the servo is then critically damped
    at SERVO_HZ for mechanism plus rotor at their heaviest.
    """
    import mujoco

    angles = np.linspace(0, 2 * np.pi, n_angles, endpoint=False)
    h = 1e-6
    turn = qpos_at(model, mech, angles + h, drive) - qpos_at(model, mech, angles - h, drive)
    v = np.angle(np.exp(1j * turn)) / (2 * h)  # every joint is a hinge: differences wrap
    data = mujoco.MjData(model)
    mass = np.zeros((model.nv, model.nv))
    inertia = 0.0
    for q, dq in zip(qpos_at(model, mech, angles, drive), v):
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        mujoco.mj_fullM(model, data, mass)
        inertia = max(inertia, float(dq @ mass @ dq))
    omega = 2 * np.pi * SERVO_HZ
    return Servo(kp=2 * inertia * omega**2, kv=4 * inertia * omega, armature=inertia)
