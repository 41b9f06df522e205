"""Straps beside forked parts (`forked_straps`, the last construction tried): a small mechanism
no earlier construction builds, where rockers sweep over ground pivots that only sheaves let
through and a crank tip carries parts that others pass between, which only a fork frees.
Refused before; built and verified in MuJoCo; a strap planted on a forked arm's layer is
caught."""

import json

import pytest
import trimesh
from planted import collision_detail, editable_copy

from linkd.mechanism import Mechanism
from linkd.verified import export_verified

# Generated (seed 7, no. 60 of 300, 7 to 13 joints), in mm: the one small mechanism of 600
# that the export refused.
TANGLED = Mechanism(
    [(-77.362, 95.919), (-43.619, 67.162), (-19.341, -39.573), (-84.724, 22.806),
     (18.219, 91.592), (-52.16, 49.289), (-62.847, -52.44), (-18.146, -59.356), (10.527, 85.756),
     (-74.649, -82.617), (11.078, 7.787), (-15.875, 63.629), (-15.52, -46.633)],
    [1, 0, 0, 1, 0, 1, 0, 0, 1, 0, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 7), (1, 9), (2, 4), (2, 10), (2, 11), (3, 4), (4, 6), (4, 7),
     (5, 6), (6, 10), (6, 11), (8, 9), (9, 12), (11, 12)],
    (0, 1), 12, units="mm",
)  # fmt: skip


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("forked_straps")
    result, report = export_verified(TANGLED, out, {"mjcf", "stl"})
    saved = json.loads((out / "mechanism.json").read_text())
    return out, result, report, {p["name"]: p for p in saved["parts"]}


def test_straps_and_forks_build_it_together(built):
    out, _, report, parts = built
    assert report.passed, report.failed
    sheaves = {p["name"]: p for p in parts.values()
               if p["kind"] == "sheave" and not p["name"].startswith("drive_")}  # fmt: skip
    assert sheaves  # some parts turn round sheaves as straps
    for name, sheave in sheaves.items():
        strap = parts[name.removesuffix("_sheave")]
        assert strap["layer"] == sheave["layer"] and strap["joints"][0] == sheave["joints"][0]
        assert strap["bore"] == pytest.approx(sheave["diameter"])
        for piece in strap["pieces"]:
            assert trimesh.load(out / piece).is_watertight
    rods = [p for p in parts.values() if p["kind"] == "pin" and p["name"][-1] in "abc"]
    assert len({p["joints"][0] for p in rods}) >= 1  # and a pin cut into rods by a fork
    assert any("arm_of" in p for p in parts.values() if not p["name"].startswith("drive_"))


def test_a_strap_planted_on_a_forked_arms_layer_is_caught(built, tmp_path):
    out, result, _, parts = built
    arm = next(p for p in parts.values() if p.get("arm_of") == result.crank)
    strap = next(parts[name.removesuffix("_sheave")] for name, p in parts.items()
                 if p["kind"] == "sheave" and not name.startswith("drive_"))  # fmt: skip
    up = arm["layer"] - strap["layer"]
    tree, geoms = editable_copy(out, tmp_path)
    pitch = (result.sizes["thickness"] + result.sizes["layer_gap"]) / 1000  # metres
    pieces = f"{strap['name']}_piece"
    moved = [g for name, g in geoms.items() if name and name.startswith(pieces)]
    assert moved and up
    for geom in moved:
        x, y, z = map(float, (geom.get("pos") or "0 0 0").split())
        geom.set("pos", f"{x} {y} {z + up * pitch}")
    detail = collision_detail(tree, tmp_path)
    assert strap["name"] in detail
