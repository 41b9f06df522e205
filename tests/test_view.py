"""`linkd view OUT`: the page it writes with --html, and the live meshcat viewer it serves."""

from __future__ import annotations

import json
import math
import re
import signal
import subprocess
import sys
import urllib.request
from pathlib import Path

from linkd.classic import crank_rocker, non_grashof_four_bar
from linkd.cli import main


def folder_with(mech, tmp_path: Path) -> Path:
    out = tmp_path / "out"
    out.mkdir()
    mech.save(out / "mechanism.json")
    return out


def test_html_only_writes_the_page(tmp_path: Path, capsys) -> None:
    out = folder_with(crank_rocker(), tmp_path)
    curve = tmp_path / "curve.csv"
    curve.write_text("x,y\n" + "\n".join(f"{x},{y}" for x, y in [(0, 0), (1, 0), (2, 1),
                     (2, 2), (1, 3), (0, 3), (-1, 2), (-1, 1)]))  # fmt: skip
    assert main(["view", str(out), "--html", "--curve", str(curve)]) == 0
    page = (out / "animation.html").read_text()
    assert "new MeshCat.Viewer" in page and "handle_command_bytearray" in page
    assert capsys.readouterr().out.strip().endswith("animation.html")


def test_target_defaults_to_the_curve_the_report_names(tmp_path: Path) -> None:
    out = folder_with(crank_rocker(), tmp_path)
    curve = tmp_path / "curve.csv"
    curve.write_text("\n".join(f"{2 * math.cos(t)},{math.sin(t)}" for t in range(0, 60, 3)))
    page = out / "animation.html"
    assert main(["view", str(out), "--html"]) == 0
    bare = page.read_bytes()
    assert main(["view", str(out), "--html", "--curve", str(curve)]) == 0
    explicit = page.read_bytes()
    (out / "report.json").write_text(json.dumps({"curve": {"file": str(curve)}}))
    assert main(["view", str(out), "--html"]) == 0
    assert page.read_bytes() == explicit != bare


def test_refuses_missing_and_invalid_input(tmp_path: Path, capsys) -> None:
    assert main(["view", str(tmp_path / "nowhere"), "--html"]) == 2
    out = folder_with(non_grashof_four_bar(), tmp_path)
    assert main(["view", str(out), "--html"]) == 1
    assert "invalid" in capsys.readouterr().err
    assert not (out / "animation.html").exists()


def test_live_viewer_serves_and_stops_on_ctrl_c(tmp_path: Path) -> None:
    out = folder_with(crank_rocker(), tmp_path)
    process = subprocess.Popen(
        [sys.executable, "-m", "linkd.cli", "view", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # Ctrl-C as at a terminal, even where the tests run in a background job (which
        # ignores SIGINT, and its children with it).
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        url = None
        for line in process.stdout:
            match = re.search(r"meshcat viewer: (http://\S+)", line)
            if match:
                url = match.group(1)
                break
        assert url, process.stderr.read()
        with urllib.request.urlopen(url, timeout=30) as reply:
            assert reply.status == 200 and b"MeshCat" in reply.read()
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=30) == 0
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
