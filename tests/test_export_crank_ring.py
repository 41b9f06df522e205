"""The crank on a ring held by a lug, beside forked parts (`forked_rings.crank_ring_layers`,
the last construction tried): the crank a disc with no pin at the motor's pivot, turning in a
ground ring whose lug's post stands in the base or hangs from the cover, driven at its rim.
Refused before; built and verified in MuJoCo; a forked arm planted on the crank's layer is
caught."""

import json

import mujoco
import pytest
import trimesh
from planted import collision_detail, editable_copy

from linkd.mechanism import Mechanism
from linkd.verified import export_verified

# Generated (seed 19, no. 12 of 200, 5 to 20 joints), in mm. Parts pass over the motor's pivot
# on both sides of the crank (plate 0-1-2) in every order, and elsewhere between the parts a
# pin carries: no shaft holds the crank, and only forks free those pins.
CRANK_RING = Mechanism(
    [(2.312, 39.834), (35.549, 20.284), (71.087, 44.255), (19.224, 23.831), (84.432, -58.107),
     (-47.922, -80.519), (-39.089, 46.346), (-95.891, -9.13), (-24.811, 41.551), (53.728, 50.762),
     (99.569, 21.164), (26.767, -55.0), (-63.616, -45.272), (-55.045, -15.07), (-48.739, 97.636)],
    [1, 0, 0, 1, 0, 1, 0, 0, 1, 0, 1, 0, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 7), (1, 12), (2, 4), (2, 6), (2, 11), (3, 4), (4, 9), (5, 6),
     (6, 7), (6, 12), (6, 13), (8, 9), (9, 13), (9, 14), (10, 11), (11, 14)],
    (0, 1), 14, units="mm",
)  # fmt: skip
CRANK = "plate_0_1_2"


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("crank_ring")
    result, report = export_verified(CRANK_RING, out, {"mjcf", "stl"})
    saved = json.loads((out / "mechanism.json").read_text())
    return out, result, report, {p["name"]: p for p in saved["parts"]}, saved["layers"]


def test_the_crank_turns_on_a_ring_held_by_a_lug(built):
    out, result, report, parts, layers = built
    assert report.passed, report.failed
    assert result.turntable == CRANK and CRANK in result.lugged and not result.drive
    pins = [p for p in parts.values() if p["kind"] == "pin"]
    assert not any(p["joints"] == [0] for p in pins)  # nothing turns on a pin at the motor
    crank = parts[CRANK]
    ring = next(p for p in parts.values() if p["kind"] == "ground" and "bore" in p
                and p["joints"] == [0])  # fmt: skip
    assert ring["layer"] == crank["layer"]
    assert ring["bore"] == pytest.approx(crank["disc"] + 2 * result.sizes["clearance"])
    (post,) = [p for p in parts.values() if p["kind"] == "post" and p["at"] == ring["posts"][0]]
    low, high = post["layers"]
    assert (low == 0 or high == layers - 1) and low <= crank["layer"] <= high
    assert any("arm_of" in p for p in parts.values())  # and forked parts beside it
    assert trimesh.load(out / crank["mesh"]).is_watertight
    model = mujoco.MjModel.from_xml_path(str(out / "mechanism.xml"))
    assert model.joint("crank").type == mujoco.mjtJoint.mjJNT_HINGE
    assert model.actuator("motor").trntype == mujoco.mjtTrn.mjTRN_JOINT


def test_a_forked_arm_planted_on_the_cranks_layer_is_caught(built, tmp_path):
    out, result, _, parts, _ = built
    arm = "link_2_4_arm0"
    below = parts[CRANK]["layer"] - parts[arm]["layer"]
    assert below > 0
    tree, geoms = editable_copy(out, tmp_path)
    pitch = (result.sizes["thickness"] + result.sizes["layer_gap"]) / 1000  # metres
    x, y, z = map(float, geoms[arm].get("pos").split())
    geoms[arm].set("pos", f"{x} {y} {z + below * pitch}")
    detail = collision_detail(tree, tmp_path)
    assert arm in detail and "ground_ring" in detail
