"""Export a mechanism and prove its MuJoCo model, with a time step fine enough for its loops.

MuJoCo closes the loops with soft constraints whose time constant is at its floor of two steps,
so the loop violation and the path error of the dynamics check fall as the square of the time
step. A mechanism close to a toggle pose can miss those tolerances at the default step. Its
model is then written again with the step that this square law says brings both under their
tolerances (a power-of-two fraction of the default, FINEST at most) and verified again, halving
further while it still falls short. Where that law says even FINEST would fall short by more
than HOPELESS, the model is not run again: the check fails as it stands. The step in
mechanism.xml is the one verified last, so `linkd verify` on the folder checks exactly that
model. A model that passes at the default step is written and verified once, as before.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

from linkd.export import TIMESTEP, ExportOptions, ExportResult, export_mechanism, set_timestep
from linkd.mechanism import Mechanism
from linkd.verify import Report, verify_output
from linkd.verify.checks import DYNAMIC_PATH_RTOL, LOOP_RTOL

FINEST = TIMESTEP / 32  # s: the finest step tried (its dynamics check runs 32 times as long)
HOPELESS = 4.0  # the square law's shortfall at FINEST beyond which no finer step is tried


def export_verified(
    mech: Mechanism,
    out_dir: Path,
    formats: set[str],
    options: ExportOptions | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[ExportResult, Report]:
    """Export `mech` into the folder `out_dir` (`formats` must include "mjcf") and verify it,
    refining the time step while only the dynamics check fails, and only on its loop-closure
    or path tolerance. The report is not written. ValueError when the export refuses `mech`.
    `progress` is told what is being done."""
    say = progress or (lambda text: None)
    export = export_mechanism(mech, out_dir, formats, options, say)
    say("verifying in MuJoCo")
    report = verify_output(out_dir, write=False)
    step = TIMESTEP
    while 1 < (excess := _excess(report)) <= HOPELESS * (step / FINEST) ** 2 and step > FINEST:
        step = max(FINEST, step / 2 ** math.ceil(math.log2(excess) / 2))
        say(f"verifying again at a time step of {step * 1e3:g} ms")
        set_timestep(out_dir, step)
        report = verify_output(out_dir, write=False)
    return export, report


def _excess(report: Report) -> float:
    """The dynamics check's loop violation and path error over their tolerances (the larger
    ratio) when it is the only check that failed, else 0: a finer step helps only then."""
    if report.failed != ["dynamics"]:
        return 0.0
    figures = report.check("dynamics").figures
    loop, path = figures.get("loop_violation", 0.0), figures.get("path_error", 0.0)
    return max(loop / LOOP_RTOL, path / DYNAMIC_PATH_RTOL)
