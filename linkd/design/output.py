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
PASSED_OVER = "passed_over"  # the folder for the best design passed over, beside the delivered one


@dataclass
class Delivered:
    """A design exported into `folder` and verified there."""

    mechanism: Mechanism
    measures: Measures
    export: ExportResult
    verification: Report
    folder: Path


@dataclass
class PassedOver:
    """A better-ranked design that was not delivered: why (one of SKIP_REASONS, and in words:
    the export's refusal or the checks MuJoCo failed) and, once measured, its curve error and
    the mechanism itself, so that the user can see and keep what was given up."""

    reason: str
    chamfer: float | None = None
    why: str = ""
    mechanism: Mechanism | None = None

    def to_dict(self) -> dict:
        measured = {} if self.chamfer is None else {"chamfer": self.chamfer}
        return {"reason": self.reason, **measured, **({"why": self.why} if self.why else {})}


def deliver(
    mech: Mechanism,
    target: np.ndarray,
    folder: Path,
    formats: set[str],
    source: dict,
    timed: bool = False,
    passed: list[PassedOver] | None = None,
    brackets: bool = True,
) -> Delivered | None:
    """Validate, export and verify `mech` into the empty `folder`; None (folder emptied) if it
    fails any step, listed in `passed` with the step ("invalid", "unbuildable": the export
    refused it, or "failed_verification") and, once measured, its curve error (what the user
    gives up). `target` is the user's curve, in the mechanism's frame (`timed`: its
    rows equally spaced in time; `brackets`: whether the export may split plates and hold
    ground pins on brackets)."""
    passed = [] if passed is None else passed
    status, _ = validate_mechanism(mech)
    if status != Status.VALID:
        passed.append(PassedOver("invalid"))
        return None
    measures = measure(mech, target, timed)
    mech = mech.replace(extra={**mech.extra, "metrics": measures.to_dict(), "source": source})
    try:
        export, report = export_verified(
            mech, folder, set(formats) | {"mjcf"}, ExportOptions(brackets=brackets)
        )
        reason = None if report.passed else "failed_verification"
        why = f"MuJoCo's checks failed: {', '.join(report.failed)}"
    except ValueError as refusal:
        reason, why = "unbuildable", str(refusal)
    if reason:
        _empty(folder)
        passed.append(PassedOver(reason, measures.chamfer, why, mech))
        return None
    return Delivered(mech, measures, export, report, folder)


def skip_counts(passed: list[PassedOver]) -> dict[str, int]:
    """How many designs were passed over for each of SKIP_REASONS."""
    return {why: sum(p.reason == why for p in passed) for why in SKIP_REASONS}


def keep_passed_over(best: PassedOver, folder: Path) -> dict:
    """Write the best design passed over, if it was measured, to `folder`/passed_over/
    mechanism.json (its metrics, and why it was passed over, among its extra keys): a designer
    may build it otherwise, or move the pins its refusal names. Its report.json entry."""
    entry = best.to_dict()
    if best.mechanism is not None:
        mech = best.mechanism
        mech = mech.replace(extra={**mech.extra, "passed_over": entry})
        (folder / PASSED_OVER).mkdir()
        mech.save(folder / PASSED_OVER / "mechanism.json")
        entry["folder"] = PASSED_OVER
    return entry


def finish(design: Delivered, target: np.ndarray, formats: set[str]) -> None:
    """Write curve.png and animation.html beside the export, then drop the MuJoCo files if
    they were only made for the proof."""
    folder = design.folder
    write_curve_plot(design.mechanism, folder / "curve.png", target=target)
    parts = parts_from_model(folder / "mechanism.xml", design.mechanism)
    write_animation(design.mechanism, folder / "animation.html", target=target, parts=parts)
    if "mjcf" not in formats:
        for name in MODEL_FILES:
            (folder / name).unlink(missing_ok=True)


def write_report(design: Delivered, report: dict) -> None:
    """report.json beside the design: `report` and the design's verification."""
    full = {**report, "verification": design.verification.to_dict()}
    write_atomic(design.folder / "report.json", json.dumps(full, indent=2) + "\n")


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
