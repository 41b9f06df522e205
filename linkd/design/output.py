"""Deliver designs: export each one, prove it in MuJoCo, and write the files of the output folder.

A design is only delivered once the exported model passes every check of `linkd verify` (with a
finer time step where its loops need one, `linkd.verified`). The MuJoCo model is always exported
for that proof; when the user did not ask for it, it is removed again once the proof is done
(the verification figures stay in report.json).
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from linkd.export import ExportOptions, ExportResult
from linkd.mechanism import Mechanism
from linkd.outdir import write_atomic
from linkd.topology import Status
from linkd.validator import validate_mechanism
from linkd.verified import export_verified
from linkd.verify import Report, write_animation, write_curve_plot
from linkd.verify.animation import parts_from_model

from .select import Measures, measure

MODEL_FILES = ("mechanism.xml", "scene.xml")
SKIP_REASONS = ("invalid", "unbuildable", "failed_verification")  # why a design is passed over


@dataclass
class Delivered:
    """A design exported into `folder` and verified there."""

    mechanism: Mechanism
    measures: Measures
    export: ExportResult
    verification: Report
    folder: Path


def deliver(
    mech: Mechanism,
    target: np.ndarray,
    folder: Path,
    formats: set[str],
    source: dict,
    timed: bool = False,
    passed: list[dict] | None = None,
    brackets: bool = True,
) -> Delivered | None:
    """Validate, export and verify `mech` into the empty `folder`; None (folder emptied) if it
    fails any step, listed in `passed` with the step ("reason": "invalid", "unbuildable": the
    export refused it, or "failed_verification") and, once measured, its curve error (what
    the user gives up). `target` is the user's curve, in the mechanism's frame (`timed`: its
    rows equally spaced in time; `brackets`: whether the export may split plates and hold
    ground pins on brackets)."""
    passed = [] if passed is None else passed
    status, _ = validate_mechanism(mech)
    if status != Status.VALID:
        passed.append({"reason": "invalid"})
        return None
    measures = measure(mech, target, timed)
    mech = mech.replace(extra={**mech.extra, "metrics": measures.to_dict(), "source": source})
    try:
        export, report = export_verified(
            mech, folder, set(formats) | {"mjcf"}, ExportOptions(brackets=brackets)
        )
        why = None if report.passed else "failed_verification"
    except ValueError:
        why = "unbuildable"
    if why:
        _empty(folder)
        passed.append({"reason": why, "chamfer": measures.chamfer})
        return None
    return Delivered(mech, measures, export, report, folder)


def skip_counts(passed: list[dict]) -> dict[str, int]:
    """How many designs were passed over for each of SKIP_REASONS."""
    return {why: sum(p["reason"] == why for p in passed) for why in SKIP_REASONS}


def finish(design: Delivered, target: np.ndarray, formats: set[str], report: dict) -> None:
    """Write curve.png, animation.html and report.json beside the export, then drop the MuJoCo
    files if they were only made for the proof."""
    folder = design.folder
    write_curve_plot(design.mechanism, folder / "curve.png", target=target)
    parts = parts_from_model(folder / "mechanism.xml", design.mechanism)
    write_animation(design.mechanism, folder / "animation.html", target=target, parts=parts)
    full = {**report, "verification": design.verification.to_dict()}
    write_atomic(folder / "report.json", json.dumps(full, indent=2) + "\n")
    if "mjcf" not in formats:
        for name in MODEL_FILES:
            (folder / name).unlink(missing_ok=True)


def summary(design: Delivered) -> dict:
    """The design's figures for report.json and the alternatives table."""
    return {
        **design.measures.to_dict(),
        "layers": design.export.layers,
        "parts": len(design.export.parts),
        "verified": design.verification.passed,
    }


def _empty(folder: Path) -> None:
    for child in folder.iterdir():
        if child.is_dir():
            shutil.rmtree(child)
        else:
            child.unlink()
