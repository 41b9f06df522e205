"""The refine stage shows its progress on a terminal (iterations, best error so far) and
nothing elsewhere."""

import io

import numpy as np
from rich.console import Console

from linkd import classic
from linkd.batch import LinkageBatch
from linkd.curves import normalise, resample
from linkd.design.refine import RefineSettings, refine
from linkd.design.select import end_effector_path
from linkd.design.stages import Stages


def test_refinement_reports_each_iteration_and_the_best_error_so_far():
    mech = classic.crank_rocker()
    target, frame = normalise(resample(end_effector_path(mech, 1000)[0], 200))
    batch = LinkageBatch.from_mechanisms([mech.transformed(frame.inverse())] * 2)
    batch.positions += np.random.default_rng(0).normal(0, 0.05, batch.positions.shape)
    calls = []
    settings = RefineSettings(iterations=12, ordered_iterations=4)
    result = refine(batch, target, settings, progress=lambda *call: calls.append(call))
    done, best = np.array(calls).T
    assert result.iterations > settings.ordered_iterations  # both phases reported
    np.testing.assert_array_equal(done, np.arange(1, result.iterations + 1))
    # The best error never rises within a phase; the second phase measures it at finer angles.
    coarse, fine = np.split(best, [settings.ordered_iterations])
    assert np.all(np.diff(coarse) <= 0) and np.all(np.diff(fine) <= 0)
    assert best[-1] == result.chamfer.min()


def test_progress_replaces_the_spinner_text_on_a_terminal_only(capsys):
    stages = Stages(show=True)
    screen = io.StringIO()
    stages.console = Console(file=screen, force_terminal=True, width=100)
    with stages.stage("refine", "refining 32 designs"):
        stages.progress("refining 32 designs: iteration 7 of 200, best Chamfer 0.0123")
    stages.progress("after the stage: not shown")
    text = screen.getvalue()
    assert "iteration 7 of 200, best Chamfer 0.0123" in text and "after the stage" not in text
    quiet = Stages(show=False)
    with quiet.stage("refine", "refining"):
        quiet.progress("iteration 1")
    assert capsys.readouterr().out == "" and quiet.seconds["refine"] >= 0
