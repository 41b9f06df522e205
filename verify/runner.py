"""`verify_output(OUT)`: run every check of an exported folder and record the report.

The design pipeline calls it on each candidate export (and moves on to the next candidate when
it fails); `linkd verify` prints its table and turns it into an exit status.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import mujoco
import numpy as np

from linkd.errors import InputError
from linkd.mechanism import UNITS_IN_METRES, Mechanism

from . import checks as c
from .collisions import check_collisions
from .dynamics import check_dynamics
from .pose import solve_sweep
from .report import Report, write_report

CHECKS = ("load", "mobility", "kinematics", "dynamics", "collisions")
THRESHOLDS = {
    "angles": c.N_ANGLES,
    "rank_rtol": c.RANK_RTOL,
    "path_rtol": c.PATH_RTOL,
    "ramp_s": c.RAMP_S,
    "settle_s": c.SETTLE_S,
    "crank_tol_rad": c.CRANK_TOL,
    "loop_rtol": c.LOOP_RTOL,
    "dynamic_path_rtol": c.DYNAMIC_PATH_RTOL,
    "min_clearance_m": 0.0,
}


def load_inputs(out_dir: Path) -> tuple[Mechanism, Path]:
    """mechanism.json (parsed) and the path of mechanism.xml; InputError when either is missing."""
    if not out_dir.is_dir():
        what = "is a file, not an output folder" if out_dir.exists() else "no such folder"
        raise InputError(f"{out_dir}: {what}")
    json_path, xml_path = out_dir / "mechanism.json", out_dir / "mechanism.xml"
    for path in (json_path, xml_path):
        if not path.is_file():
            raise InputError(f"{path}: missing (export with --export mjcf)")
    return Mechanism.load(json_path), xml_path


def verify_output(
    out_dir: str | Path,
    write: bool = True,
    progress: Callable[[str], None] | None = None,
) -> Report:
    """Check OUT/mechanism.xml against OUT/mechanism.json; merge the report into report.json.

    Raises InputError when an input is missing or malformed (nothing is written then).
    """
    out_dir = Path(out_dir)
    mech, xml_path = load_inputs(out_dir)
    say = progress or (lambda _: None)
    start = time.perf_counter()
    say("loading the model")
    load, model = c.check_load(str(xml_path))
    results = [load]
    reason = "the model did not load" if model is None else _unrunnable(model)
    if reason:
        results += [c.skipped(name, "", reason) for name in CHECKS[1:]]
    else:
        results += _physics(model, mech, say)
    report = Report(results, time.perf_counter() - start, THRESHOLDS, mujoco.__version__)
    if write:
        write_report(out_dir, report)
    return report


def _unrunnable(model: object) -> str | None:
    """Why the physics checks cannot run on this model (see the load check), if they cannot."""
    obj = mujoco.mjtObj
    names = [(obj.mjOBJ_JOINT, "crank"), (obj.mjOBJ_ACTUATOR, c.MOTOR),
             (obj.mjOBJ_SITE, c.END_EFFECTOR)]  # fmt: skip
    if any(mujoco.mj_name2id(model, kind, name) < 0 for kind, name in names):
        return "contract names missing"
    if (model.jnt_type != mujoco.mjtJoint.mjJNT_HINGE).any():
        return "joints other than hinges"
    return None


def _physics(model: object, mech: Mechanism, say: Callable[[str], None]) -> list[c.Check]:
    size = mech.scale * UNITS_IN_METRES[mech.units]
    angles = np.arange(c.N_ANGLES) * (2 * np.pi / c.N_ANGLES)
    say("solving the loops over a revolution")
    poses, lock = None, None
    try:
        poses = solve_sweep(model, mujoco.MjData(model), angles)
    except ValueError as exc:
        lock = str(exc)
    quantities = None if poses is None else c.pose_quantities(model, poses)
    jacobians = None if quantities is None else quantities["jacobian"]
    mobility = c.check_mobility(model, jacobians, angles, size, lock)
    kinematics = c.check_kinematics(mech, quantities, angles)
    say("driving the motor through a revolution")
    dynamics, contact = check_dynamics(model, mech)
    say("measuring clearances")
    collisions = check_collisions(model, poses, size, contact)
    return [mobility, kinematics, dynamics, collisions]
