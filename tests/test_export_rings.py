"""Rings round the motor's pivot (linkd.export.turntable): where the crank on a turntable does
not layer, the other parts at its pivot turn in ground rings of their own, and pins whose paths
stay inside a ring's hole cross its layer. Verified in MuJoCo; a planted collision is caught."""

import json

import numpy as np
import pytest
import trimesh
from planted import collision_detail, editable_copy

from linkd.export.parts import joint_paths
from linkd.mechanism import Mechanism
from linkd.verified import export_verified

# Generated (seed 2026, no. 16 of 200), in mm. Links 0-5 and 0-15 turn about the motor's pivot
# with the crank; the parts passing over it lie on both sides of them in every order, and
# with the crank alone on a turntable their stub crosses one. As rings they need no pin there.
RINGED = Mechanism(
    [(15.416, 28.384), (13.709, -19.777), (28.451, 51.091), (-26.653, 16.768), (-48.366, 66.102),
     (76.149, 91.672), (-24.713, -24.581), (-32.751, -35.632), (49.278, 51.644),
     (-21.105, 86.548), (94.812, -49.987), (-25.914, -8.202), (-90.991, 15.813),
     (-72.583, -92.981), (78.77, 3.918), (21.266, -72.428), (-62.133, 95.177), (3.953, 1.66)],
    [1, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 1, 0, 0, 0, 0],
    [(0, 1), (0, 5), (0, 15), (1, 3), (1, 6), (1, 9), (2, 3), (2, 4), (2, 16), (3, 4), (3, 7),
     (4, 5), (4, 6), (4, 8), (4, 9), (4, 10), (5, 7), (5, 17), (6, 14), (7, 8), (7, 12),
     (7, 15), (7, 16), (8, 10), (11, 12), (12, 17), (13, 14)],
    (0, 1), 17, units="mm",
)  # fmt: skip
RINGS = {"link_0_5": "ground_ring", "link_0_15": "ground_ring1"}


@pytest.fixture(scope="module")
def ringed(tmp_path_factory):
    out = tmp_path_factory.mktemp("ringed")
    result, report = export_verified(RINGED, out, {"mjcf", "stl"})
    return out, result, report


def test_the_parts_at_the_motors_pivot_on_rings_are_built_and_verified(ringed):
    out, result, report = ringed
    assert report.passed, report.failed
    assert result.turntable is None and set(result.rings) == set(RINGS)  # the crank on its shaft
    parts = {p["name"]: p for p in json.loads((out / "mechanism.json").read_text())["parts"]}
    pins = [p for p in parts.values() if p["kind"] == "pin"]
    shafts = [p["joins"] for p in pins if p["joints"] == [0]]  # the motor's, from base or cover
    assert len(shafts) == 1 and shafts[0][0].startswith("ground") and shafts[0][1:] == ["link_0_1"]
    paths = joint_paths(RINGED, np.linspace(0, 2 * np.pi, 720, endpoint=False))
    far = np.linalg.norm(paths - paths[0, :1], axis=-1).max(1)  # each joint's, from the pivot
    sizes, passed = result.sizes, 0
    for name, ground in RINGS.items():
        ring, bearing = parts[name], parts[ground]
        assert ring["layer"] == bearing["layer"]
        assert bearing["bore"] == pytest.approx(ring["disc"] + 2 * sizes["clearance"])
        assert 0 < ring["bore"] < ring["disc"]  # a hole
        for part in (ring, bearing):
            assert trimesh.load(out / part["mesh"]).is_watertight
        for pin in pins:  # a foreign pin crossing the ring's layer stays inside its hole
            lo, hi = pin["layers"]
            if lo <= ring["layer"] <= hi and name not in pin["joins"]:
                assert far[pin["joints"][0]] + sizes["hole_diameter"] / 2 < ring["bore"] / 2
                passed += 1
    assert passed  # and some do
    posts = [p for p in parts.values() if p["kind"] == "post"]
    top = max(parts[ground]["layer"] for ground in RINGS.values())
    ring_posts = {tuple(point) for point in parts["ground_ring"]["posts"]}
    assert ring_posts == {tuple(point) for point in parts["ground_ring1"]["posts"]}  # shared
    assert [p["layers"] for p in posts if tuple(p["at"]) in ring_posts] == [[0, top]] * 3


def test_a_planted_collision_on_a_ring_is_caught(ringed, tmp_path):
    """The outer ring's first ground piece moved in across the gap onto its ring."""
    out, result, _ = ringed
    tree, geoms = editable_copy(out, tmp_path)
    piece = geoms["ground_ring1_piece0"]  # the quadrilateral at angle 0, moved in by 3 gaps
    _, _, z = piece.get("pos").split()
    piece.set("pos", f"{-3 * result.sizes['clearance'] * 1e-3} 0 {z}")
    detail = collision_detail(tree, tmp_path)
    assert "ground_ring1_piece0" in detail and "link_0_15" in detail
