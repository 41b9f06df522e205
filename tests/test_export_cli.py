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


def test_an_export_that_fails_verification_exits_1_and_is_kept_to_inspect(
    tmp_path, capsys, monkeypatch
):
    """A defect planted in the layering (every moving part on one layer): MuJoCo finds the
    plates touching, and the folder is kept to inspect."""
    import dataclasses

    import numpy as np

    from linkd import export as exporter

    layered = exporter._layered

    def flat(*args, **kwargs):
        sizes, layout = layered(*args, **kwargs)
        return sizes, dataclasses.replace(layout, layers=np.minimum(layout.layers, 1))

    monkeypatch.setattr(exporter, "_layered", flat)
    out = tmp_path / "out"
    mech = str(EXAMPLES / "crank_rocker.json")
    assert main(["export", mech, "--out", str(out)]) == 1
    assert "failed verification: " in capsys.readouterr().out
    report = json.loads((out / "report.json").read_text())
    assert not report["verification"]["passed"] and "collisions" in report["verification"]["failed"]


def test_an_output_beside_files_linkd_does_not_write_is_not_replaced(tmp_path, capsys):
    # a project folder holding an earlier mechanism.json, the input and notes of one's own
    project = tmp_path / "project"
    project.mkdir()
    mech = project / "mechanism.json"
    classic.crank_rocker().save(mech)
    (project / "notes.txt").write_text("mine")
    assert main(["export", str(EXAMPLES / "crank_rocker.json"), "--out", str(project)]) == 2
    assert "notes.txt" in capsys.readouterr().err
    # --force replaces a folder, but never the one holding the input
    assert main(["export", str(mech), "--out", str(project), "--force"]) == 2
    assert "holds the input" in capsys.readouterr().err
    assert sorted(p.name for p in project.iterdir()) == ["mechanism.json", "notes.txt"]


def test_the_current_folder_is_never_the_output(tmp_path, monkeypatch, capsys):
    mech = tmp_path / "crank.json"
    classic.crank_rocker().save(mech)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    for out in (".", str(work), str(tmp_path)):
        assert main(["export", str(mech), "--out", out, "--force"]) == 2
        assert "current folder" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["crank.json", "work"]


def test_an_output_under_a_file_or_out_of_reach_is_refused(tmp_path, capsys):
    mech = str(EXAMPLES / "crank_rocker.json")
    afile = tmp_path / "afile"
    afile.write_text("")
    assert main(["export", mech, "--out", str(afile / "sub")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    assert main(["export", mech, "--out", "/proc/no/such"]) == 2
    assert "cannot make the folder" in capsys.readouterr().err
    assert not Path("/proc/no").exists()


def test_a_failed_run_leaves_no_folders_it_made(tmp_path, monkeypatch):
    from linkd import outdir

    deep = tmp_path / "a" / "b" / "out"
    with pytest.raises(RuntimeError), outdir.staged_output(deep):
        assert deep.parent.is_dir()
        raise RuntimeError("stopped part-way")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "args, named",
    [
        (["--export", "step"], "step"),
        (["--hole-diameter", "1000"], "hole diameter (1000)"),
        (["--thickness", "-1"], "thickness"),
        (["--link-width", "-1"], "link width"),
        (["--link-width", "nan"], "link width"),
        (["--density", "0"], "density"),
        (["--link-width", "80"], "least spacing of two joints of a part (15)"),  # holes merge
    ],
)
def test_bad_options_exit_2_and_write_nothing(tmp_path, capsys, args, named):
    out = tmp_path / "out"
    assert main(["export", str(EXAMPLES / "jansen_leg.json"), "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0]
    assert not out.exists()


def test_malformed_and_invalid_mechanisms(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "linkd-mechanism/1", "nodes": []}')
    out = tmp_path / "out"
    assert main(["export", str(bad), "--out", str(out)]) == 2
    locked = tmp_path / "locked.json"
    classic.non_grashof_four_bar().save(locked)
    assert main(["export", str(locked), "--out", str(out)]) == 1
    assert "locks" in capsys.readouterr().err
    assert not out.exists()


def test_a_hole_the_usual_width_holds_is_built_however_narrow_the_fallbacks(tmp_path):
    """The narrower widths tried when the usual one does not layer are left out where they
    cannot hold the hole asked for; the usual width still builds."""
    from linkd.export.options import resolve_sizes
    from linkd.export.parts import assemble
    from linkd.mechanism import Mechanism

    mech = Mechanism.load(EXAMPLES / "crank_rocker.json")
    usual = resolve_sizes(mech, assemble(mech).parts, None)
    hole = str(0.5 * usual.link_width)  # wider than a quarter of the width
    args = ["export", str(EXAMPLES / "crank_rocker.json"), "--hole-diameter", hole]
    assert main([*args, "--out", str(tmp_path / "out"), "--export", "mjcf"]) == 0
