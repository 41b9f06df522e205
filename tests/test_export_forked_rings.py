"""Ground pivots on rings beside forked parts (linkd.export.forked_rings): the last construction
tried, so a mechanism it builds was refused by every other. Built and verified in MuJoCo, the
parts at one ground pivot on rings held by a lug and other parts forked into arms with their
pins cut into rods; a fork's arm planted on a ring's layer is caught."""

import json

import mujoco
import pytest
import trimesh
from planted import collision_detail, editable_copy

from linkd.mechanism import Mechanism
from linkd.verified import export_verified

# Generated (seed 13, no. 30 of 200, 5 to 20 joints), in mm. The parts at ground pivot 3 sweep
# over pins on both sides of them in every order, and elsewhere parts pass between the parts
# a pin carries in every order: rings alone, or forks alone, do not layer it.
FORKED = Mechanism(
    [(-0.146, 7.957), (-35.865, 21.011), (79.763, 28.886), (-5.717, -5.518), (-51.507, 52.69),
     (74.177, 25.763), (41.149, 78.942), (-79.793, -78.454), (71.976, -30.39), (-58.576, -50.554),
     (9.07, -87.411), (35.97, -73.265), (-87.244, 62.813), (6.146, 74.236), (-21.887, 7.688),
     (-36.255, -76.241), (85.606, -10.253)],
    [1, 0, 0, 1, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 6), (1, 7), (1, 10), (2, 4), (2, 13), (3, 4), (3, 7), (3, 12),
     (5, 6), (5, 14), (6, 9), (6, 12), (6, 14), (6, 15), (8, 9), (8, 10), (8, 11), (9, 11),
     (9, 16), (10, 16), (12, 13), (14, 15)],
    (0, 1), 16, units="mm",
)  # fmt: skip
RINGED = {"link_3_4", "link_3_7", "link_3_12"}  # the parts at ground pivot 3


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("forked_rings")
    result, report = export_verified(FORKED, out, {"mjcf", "stl"})
    parts = {p["name"]: p for p in json.loads((out / "mechanism.json").read_text())["parts"]}
    return out, result, report, parts


def test_rings_at_one_pivot_and_forked_parts_elsewhere(built):
    out, result, report, parts = built
    assert report.passed, report.failed
    assert set(result.lugged) == RINGED and not result.turntables and not result.drive
    pins = [p for p in parts.values() if p["kind"] == "pin"]
    assert not any(p["joints"] == [3] for p in pins)  # no pin at the ringed pivot
    forked = {p["arm_of"] for p in parts.values() if "arm_of" in p and p["kind"] == "link"}
    assert forked  # links made as arms, one per part they carry: forks
    for link in forked:
        arms = [p for p in parts.values() if p.get("arm_of") == link]
        assert len(arms) >= 2 and len({a["layer"] for a in arms}) == len(arms)
        cut = [p for p in pins if p.get("fixed_in") == link and len(p["joins"]) == 2]
        assert len(cut) >= 2  # its pins cut into rods, each carrying one part
    (post,) = [p for p in parts.values() if p["kind"] == "post"]
    top = json.loads((out / "mechanism.json").read_text())["layers"] - 1
    low, high = post["layers"]
    assert low == 0 or high == top  # from the base or the cover
    for name in RINGED:
        ring = parts[name]
        bearing = next(p for p in parts.values() if p["kind"] == "ground" and "bore" in p
                       and p["layer"] == ring["layer"])  # fmt: skip
        assert bearing["posts"] == [post["at"]] and low <= ring["layer"] <= high
        assert bearing["bore"] == pytest.approx(ring["disc"] + 2 * result.sizes["clearance"])
        assert trimesh.load(out / ring["mesh"]).is_watertight
    model = mujoco.MjModel.from_xml_path(str(out / "mechanism.xml"))
    assert all(model.joint(f"hinge_{name}").type == mujoco.mjtJoint.mjJNT_HINGE for name in RINGED)


def test_a_forks_arm_planted_on_a_rings_layer_is_caught(built, tmp_path):
    """An arm of a forked link moved down onto the layer of the ring it clears at the pose:
    the two meet part way round the revolution, and verification says which."""
    out, result, _, parts = built
    arm, ring = parts["link_10_16_arm0"], parts["link_3_12"]
    assert arm["layer"] > ring["layer"]
    tree, geoms = editable_copy(out, tmp_path)
    pitch = (result.sizes["thickness"] + result.sizes["layer_gap"]) / 1000  # metres
    geom = geoms["link_10_16_arm0"]
    x, y, z = map(float, geom.get("pos").split())
    geom.set("pos", f"{x} {y} {z - (arm['layer'] - ring['layer']) * pitch}")
    detail = collision_detail(tree, tmp_path)
    assert "link_10_16_arm0" in detail and "link_3_12" in detail
