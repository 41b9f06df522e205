"""animation.html opens in headless Chromium with no JavaScript error and draws with WebGL.

Chromium is driven over its DevTools protocol (a websocket; no browser driver needed). The test
is skipped only when no Chromium is installed (`apt-get install chromium`; .ci/run does it).
"""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from linkd.classic import crank_rocker, jansen_leg
from linkd.verify.analytic import joint_paths
from linkd.verify.animation import page, prism, rounded_outline, scene_commands, write_animation

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=800,600",
    "--remote-debugging-port=0",
]
PROBE = """(() => {
  const gl = viewer.renderer.getContext();
  const parts = viewer.scene_tree.find(["meshcat", "linkd", "parts"]);
  return {
    webgl: gl instanceof WebGLRenderingContext || gl instanceof WebGL2RenderingContext,
    canvas: document.querySelectorAll("canvas").length,
    width: viewer.renderer.domElement.width,
    triangles: viewer.renderer.info.render.triangles,
    parts: Object.keys(parts.children).length,
    actions: viewer.animator.actions.length,
    playing: viewer.animator.actions.some(a => a.isRunning()),
  };
})()"""


class DevTools:
    """A minimal DevTools-protocol client for one page: commands in order, events collected."""

    def __init__(self, url: str) -> None:
        from websockets.sync.client import connect

        self.socket = connect(url, max_size=None, legacy=True)
        self.events: list[dict] = []
        self.next_id = 0

    def send(self, method: str, **params: object) -> dict:
        self.next_id += 1
        self.socket.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            message = json.loads(self.socket.recv(timeout=60))
            if message.get("id") == self.next_id:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message["result"]
            self.events.append(message)

    def wait_for(self, event: str, timeout: float = 60) -> None:
        deadline = time.monotonic() + timeout
        while not any(e.get("method") == event for e in self.events):
            self.events.append(json.loads(self.socket.recv(timeout=deadline - time.monotonic())))

    def errors(self) -> list[str]:
        found = []
        for e in self.events:
            method, params = e.get("method"), e.get("params", {})
            if method == "Runtime.exceptionThrown":
                found.append(json.dumps(params["exceptionDetails"])[:500])
            elif method == "Runtime.consoleAPICalled" and params["type"] in ("error", "assert"):
                found.append(json.dumps(params["args"])[:500])
            elif method == "Log.entryAdded" and params["entry"]["level"] == "error":
                found.append(params["entry"]["text"][:500])
        return found


def open_in_chromium(html_file: Path, screenshot: Path) -> tuple[dict, list[str]]:
    """Load a page, let it play a second, return the probe's answer and any JavaScript errors."""
    profile = html_file.parent / "chromium-profile"
    profile.mkdir()
    log = (html_file.parent / "chromium.log").open("w")
    browser = subprocess.Popen(
        [CHROMIUM, *FLAGS, f"--user-data-dir={profile}", "about:blank"],
        stdout=log,
        stderr=log,
    )
    try:
        port_file = profile / "DevToolsActivePort"  # Chromium writes its port here
        deadline = time.monotonic() + 60
        while not (port_file.exists() and port_file.read_text().strip()):
            assert browser.poll() is None, "Chromium exited; see chromium.log"
            assert time.monotonic() < deadline, "Chromium did not open its DevTools port"
            time.sleep(0.1)
        port = port_file.read_text().split()[0]
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=30) as reply:
            targets = json.load(reply)
        page_url = next(t["webSocketDebuggerUrl"] for t in targets if t["type"] == "page")
        tools = DevTools(page_url)
        for domain in ("Runtime", "Log", "Page"):
            tools.send(f"{domain}.enable")
        tools.send("Page.navigate", url=html_file.resolve().as_uri())
        tools.wait_for("Page.loadEventFired")
        time.sleep(1.0)  # let the animation run some frames
        probe = tools.send("Runtime.evaluate", expression=PROBE, returnByValue=True)
        if "exceptionDetails" in probe:
            raise AssertionError(f"probe failed: {probe['exceptionDetails']}")
        shot = tools.send("Page.captureScreenshot", format="png")
        screenshot.write_bytes(base64.b64decode(shot["data"]))
        tools.socket.close()
        return probe["result"]["value"], tools.errors()
    finally:
        browser.terminate()
        browser.wait(timeout=30)
        log.close()


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium)")
def test_animation_page_loads_and_draws_webgl(tmp_path: Path) -> None:
    mech = jansen_leg()
    target = joint_paths(mech, 64)[mech.end_effector] + 1.0
    html_file = tmp_path / "animation.html"
    write_animation(mech, html_file, target)
    screenshot = tmp_path / "animation.png"
    probe, errors = open_in_chromium(html_file, screenshot)
    assert errors == []
    assert probe["webgl"] and probe["canvas"] >= 1 and probe["width"] > 0
    assert probe["triangles"] > 0, "the renderer drew nothing"
    assert probe["parts"] == 8  # ground, crank, four bars and two ternary plates
    assert probe["actions"] == 8 and probe["playing"]
    from PIL import Image

    pixels = np.asarray(Image.open(screenshot).convert("RGB"))
    assert pixels.shape[0] > 100 and len(np.unique(pixels.reshape(-1, 3), axis=0)) > 50


def test_page_is_standalone() -> None:
    """No network at view time: no external script or stylesheet, no fetch, no websocket."""
    text = page(scene_commands(crank_rocker()), "t")
    assert not re.search(r"<script[^>]*\ssrc=|<link\b", text)
    commands = text.split("<script>")[-1]
    assert "new MeshCat.Viewer" in commands and "handle_command_bytearray" in commands
    assert "fetch(" not in commands and "connect(" not in commands


def test_parts_follow_the_joints() -> None:
    """The animated transform of each part carries its joints along their analytic paths."""
    from linkd.verify.animation import FRAMES, default_parts, part_displacements

    mech = jansen_leg()
    paths = joint_paths(mech, FRAMES)
    for part in default_parts(mech):
        poses = part_displacements(part, paths)
        for j in part.joints:
            start = np.r_[mech.positions[j], 0.0, 1.0]
            moved = (poses @ start)[:, :2]
            np.testing.assert_allclose(moved, paths[j], atol=1e-9 * mech.scale)


def test_prism_is_closed_and_outward() -> None:
    outline = rounded_outline(np.array([[0.0, 0.0], [3.0, 1.0]]), 0.5)
    vertices, faces = prism(outline, 0.0, 0.2)
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all()  # watertight: every edge shared by exactly two faces
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    x, y = outline.T
    area = 0.5 * (x * np.roll(y, -1) - np.roll(x, -1) * y).sum()
    assert volume == pytest.approx(0.2 * area, rel=1e-9)  # positive: faces point outwards
