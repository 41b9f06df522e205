"""Deliver designs: export each one, prove it in MuJoCo, and write the files of the output folder.

A design is only delivered once the exported model passes every check of `linkd verify` (with a
finer time step where its loops need one, `linkd.verified`). The MuJoCo model is always exported
for that proof; when the user did not ask for it, it is removed again once the proof is done
(the verification figures stay in report.json).
"""

from __future__ import annotations

import json
import shutil
from collections import Counter
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
    skipped: Counter | None = None,
    brackets: bool = True,
    passed: list[dict] | None = None,
) -> Delivered | None:
    """Validate, export and verify `mech` into the empty `folder`; None (folder emptied) if it
    fails any step, counted in `skipped` by the step ("invalid", "unbuildable": the export
    refused it, "failed_verification") and listed in `passed` with its curve error once
    measured (what the user gives up). `target` is the user's curve, in the mechanism's frame
    (`timed`: its rows equally spaced in time; `brackets`: whether the export may split
    plates and hold ground pins on brackets)."""
    skipped = Counter() if skipped is None else skipped
    passed = [] if passed is None else passed
    status, _ = validate_mechanism(mech)
    if status != Status.VALID:
        skipped["invalid"] += 1
        passed.append({"reason": "invalid"})
        return None
    measures = measure(mech, target, timed)
    mech = mech.replace(extra={**mech.extra, "metrics": measures.to_dict(), "source": source})
    try:
        export, report = export_verified(mech, folder, set(formats) | {"mjcf"},
                                         ExportOptions(brackets=brackets))
        why = None if report.passed else "failed_verification"
    except ValueError:
        why = "unbuildable"
    if why:
        _empty(folder)
        skipped[why] += 1
        passed.append({"reason": why, "chamfer": measures.chamfer})
        return None
    return Delivered(mech, measures, export, report, folder)


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
