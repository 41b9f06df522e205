"""A forked crank cut in two at the motor, beside a ground pivot on rings (linkd.export
.forked_rings with the crank's shaft cut, linkd.export.drive): the crank's arms at the motor on
stubs from base and cover, both halves reaching the crank tip, each with its own rod there,
the halves turned as one by the layshaft. Refused before; built and verified in MuJoCo; an arm
of the upper half planted between the halves is caught."""

import json

import mujoco
import pytest
from planted import collision_detail, editable_copy

from linkd.mechanism import Mechanism
from linkd.verified import export_verified

# Generated (seed 31, no. 2 of 100, 5 to 20 joints), in mm. With ground pivot 3's parts on rings
# and other parts forked it layers only if parts pass over the motor's pivot between the arms
# of the crank (plate 0-1-2), two of which end at its tip, joint 1.
CUT_FORK = Mechanism(
    [(70.189, -5.244), (53.033, -38.057), (-76.982, 24.588), (43.203, 47.297), (60.702, -69.612),
     (50.723, 92.151), (-83.467, -14.386), (-61.53, 55.779), (87.511, -14.669), (-89.834, -15.872),
     (-54.847, 65.066), (18.29, -90.755), (88.104, -97.442), (-43.84, -25.875), (-8.824, 71.457),
     (-21.174, -79.383)],
    [1, 0, 0, 1, 0, 1, 0, 1, 0, 0, 1, 0, 1, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 6), (1, 15), (2, 4), (3, 4), (4, 14), (5, 6), (5, 9), (6, 8),
     (6, 9), (7, 8), (8, 11), (8, 13), (10, 11), (12, 13), (13, 14), (14, 15)],
    (0, 1), 15, units="mm",
)  # fmt: skip
CRANK, UPPER = "plate_0_1_2", "plate_0_1_2_upper"


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("forked_cut")
    result, report = export_verified(CUT_FORK, out, {"mjcf", "stl"})
    parts = {p["name"]: p for p in json.loads((out / "mechanism.json").read_text())["parts"]}
    return out, result, report, parts


def test_a_forked_crank_cut_in_two_is_built_and_verified(built):
    out, result, report, parts = built
    assert report.passed, report.failed
    assert result.drive == "drive_layshaft" and result.lugged  # and a pivot on rings
    lower = [p for p in parts.values() if p.get("arm_of") == CRANK]
    upper = [p for p in parts.values() if p.get("arm_of") == UPPER]
    assert lower and upper and max(a["layer"] for a in lower) < min(a["layer"] for a in upper)
    stubs = {p["name"]: p["fixed_in"] for p in parts.values() if p["name"].startswith("pin_0")}
    assert stubs == {"pin_0": CRANK, "pin_0_top": UPPER}
    tip = [p for p in parts.values() if p["kind"] == "pin" and p["joints"] == [1]]
    assert sorted(p["fixed_in"] for p in tip) == [CRANK, UPPER]  # a rod in each half
    for rod in tip:  # each carries one part, on the layers of its own half's arm
        arm = next(a for a in lower + upper if a["arm_of"] == rod["fixed_in"] and 1 in a["joints"])
        assert rod["joins"][0] == rod["fixed_in"] and len(rod["joins"]) == 2
        low, high = rod["layers"]
        assert low <= arm["layer"] <= high
    model = mujoco.MjModel.from_xml_path(str(out / "mechanism.xml"))
    assert model.joint(f"hinge_{UPPER}").type == mujoco.mjtJoint.mjJNT_HINGE


def test_an_upper_arm_planted_between_the_halves_is_caught(built, tmp_path):
    """The upper half's arm moved down among the parts that pass over the motor's pivot: it
    clears them at the pose and meets one part way round."""
    out, result, _, parts = built
    (arm,) = [name for name, p in parts.items() if p.get("arm_of") == UPPER]
    passing = parts["link_8_11"]
    assert parts[arm]["layer"] > passing["layer"]
    tree, geoms = editable_copy(out, tmp_path)
    pitch = (result.sizes["thickness"] + result.sizes["layer_gap"]) / 1000  # metres
    x, y, z = map(float, geoms[arm].get("pos").split())
    geoms[arm].set("pos", f"{x} {y} {z - (parts[arm]['layer'] - passing['layer']) * pitch}")
    detail = collision_detail(tree, tmp_path)
    assert f"{arm} / link_8_11" in detail and "crank angle 0.0 deg" not in detail
