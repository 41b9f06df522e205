"""`linkd design` on the command line: exit codes, messages, the output folder's name."""

import json
from pathlib import Path

import numpy as np
import pytest

from linkd.cli import main

EXAMPLES = Path(__file__).resolve().parents[1] / "assets" / "examples"

BAD_CURVES = {
    "nan.csv": "x,y\n0,0\n1,0\nnan,1\n" + "".join(f"{k},{k * k}\n" for k in range(2, 10)),
    "one_column.csv": "".join(f"{k}\n" for k in range(12)),
    "few.csv": "0,0\n1,0\n1,1\n0,1\n",
    # a loop squashed onto one line (out on even steps, back on odd ones); a straight open
    # stroke is a valid path (tests/test_open_paths.py)
    "line.csv": "".join(f"{k},{2 * k}\n" for k in [*range(0, 12, 2), *range(11, 0, -2)]),
    "same.csv": "3,4\n" * 12,
    "text.csv": "x,y\n" + "".join(f"{k},{k % 3}\n" for k in range(10)) + "a,b\n",
    "huge.csv": "".join(f"{k}e306,{(k * k) % 7}e305\n" for k in range(-5, 6)),  # no overflow
}


@pytest.mark.parametrize("name", sorted(BAD_CURVES))
def test_bad_curve_exits_2_with_one_line_and_writes_nothing(tmp_path, monkeypatch, capsys, name):
    monkeypatch.chdir(tmp_path)
    (tmp_path / name).write_text(BAD_CURVES[name])
    assert main(["design", name]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and name in err[0]
    assert [p.name for p in tmp_path.iterdir()] == [name]


def test_missing_curve_and_bad_options_exit_2(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["design", "absent.csv"]) == 2
    assert "absent.csv" in capsys.readouterr().err
    curve = str(EXAMPLES / "ellipse.csv")
    (tmp_path / "not_a_model.pt").write_text("weights")
    for args in (["--candidates", "0"], ["--export", "step"], ["--time-budget", "0"],
                 ["--time-budget", "inf"], ["--units", "furlong"], ["--strategy", "best"],
                 ["--top", "-1"], ["--proposer", "oracle"], ["--model", "not_a_model.pt"],
                 ["--model", "."], ["--atlas", "not_a_model.pt"]):  # fmt: skip
        assert main(["design", curve, *args]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == [tmp_path / "not_a_model.pt"]


def test_design_example_curve_with_the_shipped_model(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    curve = str(EXAMPLES / "ellipse.csv")
    args = ["design", curve, "--export", "mjcf,stl", "--candidates", "32"]
    assert main(args) == 0
    out = tmp_path / "ellipse-design"
    report = json.loads((out / "report.json").read_text())
    assert report["verification"]["passed"]
    assert report["design"]["chamfer"] < 0.1
    assert (out / "mechanism.xml").is_file() and list((out / "meshes").glob("*.stl"))
    assert "verified" in capsys.readouterr().out
    # A second run does not overwrite the first: it takes a fresh name, the one the summary
    # names the folder by in every line (relative, as the first run's name is). A shorter budget
    # serves: this run is about the name and the summary.
    assert main([*args, "--export", "stl", "--top", "1", "--time-budget", "10"]) == 0
    assert (tmp_path / "ellipse-design-2" / "mechanism.json").is_file()
    printed = capsys.readouterr().out
    assert printed.startswith("ellipse-design-2: ") and str(tmp_path) not in printed
    for line in printed.splitlines():
        assert "alternatives/" not in line or "ellipse-design-2/alternatives/" in line
    listed = [line for line in printed.splitlines() if "alternative 1:" in line]
    assert len(listed) == 1 and "footprint" in listed[0] and "transmission angle" in listed[0]
    assert not (tmp_path / "ellipse-design-2" / "mechanism.xml").exists()


def test_random_proposer_designs_blind_to_the_curve(tmp_path, monkeypatch):
    from linkd.design.propose import random_proposer

    monkeypatch.chdir(tmp_path)
    curve = str(EXAMPLES / "ellipse.csv")
    args = ["design", curve, "--export", "mjcf", "--candidates", "32", "--proposer", "random",
            "--time-budget", "10"]  # fmt: skip
    assert main([*args, "--out", "a"]) == 0
    report = json.loads((tmp_path / "a" / "report.json").read_text())
    assert report["search"]["proposer"] == "random" and "model" not in report["search"]
    assert "random" in report["search"]["sources"] and "model" not in report["search"]["sources"]
    assert report["search"]["found_by"] in ("random", "atlas", "round 2")
    assert report["verification"]["passed"]
    propose = random_proposer()
    curves = np.zeros((2, 200, 2), np.float32)
    first, again = propose(curves, 3, 0), propose(curves + 1, 3, 0)
    assert first.shape == (6, 20, 24) and np.array_equal(first, again)  # blind and repeatable
    assert not np.array_equal(first, propose(curves, 3, 1))


def test_a_terminated_design_leaves_nothing_behind(tmp_path):
    """SIGTERM, as a CI job's timeout sends it, cleans up as Ctrl-C does."""
    import subprocess
    import sys
    import time

    out = tmp_path / "out"
    run = subprocess.Popen([sys.executable, "-m", "linkd.cli", "design",
                            str(EXAMPLES / "crescent.csv"), "--out", str(out)],
                           stderr=subprocess.PIPE, text=True)  # fmt: skip
    until = time.monotonic() + 60
    while not list(tmp_path.glob(".out.*")) and time.monotonic() < until:
        time.sleep(0.05)  # the staging folder appears once the curve is read
    assert list(tmp_path.glob(".out.*")), "the design never began its output"
    run.terminate()
    _, err = run.communicate(timeout=60)
    assert run.returncode == 143 and err.strip().splitlines() == ["linkd: terminated"]
    assert list(tmp_path.iterdir()) == []


def test_a_termination_swallowed_on_the_way_still_ends_the_run(tmp_path, capsys):
    """Raised inside a finaliser (as the garbage collector may run one anywhere), Terminated is
    swallowed; the run still ends at its next stage, or before its output is put in place."""
    import signal

    from linkd.design.stages import Stages
    from linkd.outdir import staged_output
    from linkd.termination import Terminated, on_sigterm, sigterm_raises

    class Finaliser:
        def __del__(self):
            on_sigterm(signal.SIGTERM, None)

    with sigterm_raises():
        with pytest.raises(Terminated), staged_output(tmp_path / "out") as stage:
            Finaliser()  # collected at once: the handler's Terminated goes nowhere
            (stage / "mechanism.json").write_text("{}")  # and the run goes on
        with pytest.raises(Terminated), Stages(show=False).stage("next", "the next stage"):
            pass
    assert list(tmp_path.iterdir()) == []
    assert "Terminated" not in capsys.readouterr().err  # not reported as an ignored exception


def test_the_one_shot_setting_is_the_models_single_sample_alone(tmp_path):
    """CONTRACT §5: no atlas path or sub-mechanism stands in for an invalid sample (today seeds
    0-3 are invalid on this curve and exit 1, seed 4 is delivered)."""
    for seed in range(5):
        out = tmp_path / str(seed)
        args = ["--strategy", "oneshot", "--candidates", "1", "--no-refine", "--seed", str(seed)]
        code = main(["design", str(EXAMPLES / "crescent.csv"), *args, "--out", str(out)])
        if code == 0:
            report = json.loads((out / "report.json").read_text())
            assert report["search"]["found_by"] == "model"
            assert set(report["search"]["sources"]) == {"model"}
        else:
            assert code == 1 and not out.exists()


def test_a_budget_too_short_to_refine_says_so(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["design", str(EXAMPLES / "ellipse.csv"), "--time-budget", "9", "--out", str(out)]
    assert main(args) == 0
    assert json.loads((out / "report.json").read_text())["search"]["budget_cut_refinement"]
    assert "the time budget (9 s) cut refinement short" in capsys.readouterr().out
