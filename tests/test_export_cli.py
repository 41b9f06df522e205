"""`linkd export`: the output folder of CONTRACT §4, exit codes, nothing half-written."""

import json
from pathlib import Path

import pytest

from linkd import classic
from linkd.cli import main

EXAMPLES = Path(__file__).resolve().parents[1] / "assets" / "examples"


def test_export_writes_the_output_folder(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["export", str(EXAMPLES / "crank_rocker.json"), "--out", str(out)]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"mechanism.json", "mechanism.xml", "scene.xml", "meshes", "animation.html",
            "curve.png", "report.json"} <= names  # fmt: skip
    full = json.loads((out / "report.json").read_text())
    report = full["export"]
    saved = json.loads((out / "mechanism.json").read_text())
    assert report["layers"] == saved["layers"]
    assert report["parts"] == {"ground": 1, "link": 2, "plate": 1, "pin": 4}
    assert full["verification"]["passed"]  # the model written, proved as `linkd verify` does
    assert "verified in MuJoCo" in capsys.readouterr().out
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no staging left


def test_export_shows_its_stages_on_a_terminal(tmp_path, monkeypatch):
    import io

    from rich.console import Console

    from linkd.commands import export
    from linkd.design.stages import Stages

    screen = io.StringIO()

    def on_a_terminal() -> Stages:
        stages = Stages(show=True)
        stages.console = Console(file=screen, force_terminal=True, width=100)
        return stages

    monkeypatch.setattr(export, "Stages", on_a_terminal)
    out = tmp_path / "out"
    assert main(["export", str(EXAMPLES / "crank_rocker.json"), "--out", str(out)]) == 0
    layers = json.loads((out / "mechanism.json").read_text())["layers"]
    text = screen.getvalue()
    assert f"export   {layers} layers, verified in MuJoCo" in text and "write" in text


def test_export_replaces_its_own_output_and_refuses_other_folders(tmp_path):
    mech = str(EXAMPLES / "crank_rocker.json")
    out = tmp_path / "out"
    assert main(["export", mech, "--out", str(out), "--export", "mjcf"]) == 0
    assert main(["export", mech, "--out", str(out), "--export", "stl"]) == 0
    assert (out / "meshes").is_dir() and not (out / "mechanism.xml").exists()
    assert "verification" not in json.loads((out / "report.json").read_text())  # no model
    other = tmp_path / "notes"
    other.mkdir()
    (other / "keep.txt").write_text("mine")
    assert main(["export", mech, "--out", str(other)]) == 2
    assert [p.name for p in other.iterdir()] == ["keep.txt"]
    assert main(["export", mech, "--out", str(other), "--force"]) == 0
    assert (other / "mechanism.json").exists()


@pytest.mark.parametrize(
    "args",
    [["--export", "step"], ["--hole-diameter", "1000"], ["--thickness", "-1"]],
)
def test_bad_options_exit_2_and_write_nothing(tmp_path, capsys, args):
    out = tmp_path / "out"
    assert main(["export", str(EXAMPLES / "jansen_leg.json"), "--out", str(out), *args]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not out.exists()


def test_malformed_and_invalid_mechanisms(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "linkd-mechanism/1", "nodes": []}')
    out = tmp_path / "out"
    assert main(["export", str(bad), "--out", str(out)]) == 2
    locked = tmp_path / "locked.json"
    classic.non_grashof_four_bar().save(locked)
    assert main(["export", str(locked), "--out", str(out)]) == 1
    assert "locks" in capsys.readouterr().out
    assert not out.exists()
