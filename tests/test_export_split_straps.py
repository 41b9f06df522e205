"""Split plates with straps (linkd.export.braced.split_straps_layers): a plate cut into arms
and links made straps round sheaves at once. Neither construction builds the mechanism alone;
together they do, verified in MuJoCo, and a strap planted over a pin its sheave lets through
is caught. An arm of a split plate may be a strap itself."""

import json

import pytest
import trimesh
from test_export_strapped import sheaves_crossed, strap_moved_onto

from linkd.export.braced import braced_layers
from linkd.export.layers import NoFlatLayers, sweep
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.export.strapped import several_straps_layers, strapped_layers
from linkd.mechanism import Mechanism
from linkd.verified import export_verified

# Generated (seed 99, no. 62 of 200), in mm. The crank plate (eight joints) must be cut so
# that the parts it carries turn on both sides of its arms, and links 1-12, 2-7 and 13-14 pass
# over the motor's shaft and the crank's pins, which must cross their layers through sheaves.
SPLIT_STRAPPED = Mechanism(
    [(23.595, 80.812), (30.037, 68.165), (59.57, 51.009), (55.923, 45.684), (-7.529, -63.448),
     (-41.947, 83.219), (-44.537, -25.245), (46.849, -40.489), (84.871, 63.855),
     (-38.636, 29.937), (-8.16, -79.033), (-73.148, 3.058), (-37.242, 68.644),
     (-21.521, 83.561), (32.787, 23.211), (67.897, -10.202), (-29.998, -11.17),
     (90.504, -23.184), (82.682, 82.492)],
    [1, 0, 0, 0, 1, 0, 1, 0, 0, 0, 0, 1, 0, 1, 0, 0, 1, 0, 0],
    [(0, 1), (0, 2), (0, 9), (1, 2), (1, 3), (1, 5), (1, 8), (1, 12), (1, 15), (2, 3), (2, 7),
     (2, 8), (2, 15), (3, 9), (3, 10), (4, 5), (5, 18), (6, 7), (9, 10), (9, 14), (10, 18),
     (11, 12), (12, 17), (13, 14), (16, 17)],
    (0, 1), 18, units="mm",
)  # fmt: skip
CRANK = "plate_0_1_2_3_8_9_10_15"
SHEAVES = {"link_1_12_sheave": CRANK, "link_2_7_sheave": CRANK, "link_13_14_sheave": "ground"}

# Generated (seed 41, no. 69 of 100), in mm: plate 1-4-8-9 is cut into a star at 4, and its
# arm 1-4 turns on a sheave of the crank at 1 that lets the motor's shaft through.
ARM_STRAPPED = Mechanism(
    [(-1.615, 82.314), (-12.226, 77.196), (39.54, 29.866), (-21.384, 10.908), (72.268, 82.953),
     (73.133, -73.917), (1.039, 18.983), (-53.87, -54.524), (15.016, -73.082), (85.789, -18.235),
     (87.167, 87.506), (-1.282, 89.294), (43.699, 7.196), (-52.481, 93.187), (-70.663, 33.596)],
    [1, 0, 0, 1, 0, 1, 0, 0, 0, 0, 0, 1, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 4), (1, 7), (1, 8), (2, 7), (2, 14), (3, 4), (3, 10), (4, 6),
     (4, 8), (4, 9), (5, 6), (7, 13), (8, 9), (8, 10), (9, 14), (10, 12), (11, 12), (12, 13)],
    (0, 1), 14, units="mm",
)  # fmt: skip
ARM = "plate_1_4_8_9_arm0"


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("split_strapped")
    result, report = export_verified(SPLIT_STRAPPED, out, {"mjcf", "stl"})
    return out, result, report


@pytest.mark.parametrize("layering", [braced_layers, strapped_layers, several_straps_layers])
def test_split_plates_or_straps_alone_do_not_build_it(layering):
    assembly = assemble(SPLIT_STRAPPED)
    sizes = resolve_sizes(SPLIT_STRAPPED, assembly.parts, None)
    with pytest.raises(NoFlatLayers):
        layering(assembly, sweep(SPLIT_STRAPPED, sizes.link_width), sizes)


def test_split_plates_with_straps_are_built_and_verified(built):
    out, result, report = built
    assert report.passed, report.failed
    assert result.narrowed == 1.0  # at the usual width
    parts = {p["name"]: p for p in json.loads((out / "mechanism.json").read_text())["parts"]}
    assert {n: p["fixed_in"] for n, p in parts.items() if p["kind"] == "sheave"} == SHEAVES
    assert sheaves_crossed(SPLIT_STRAPPED, out, parts, SHEAVES)  # some pins cross through
    arms = [p for p in parts.values() if p.get("arm_of") == CRANK and p["kind"] == "plate"]
    assert len({p["layer"] for p in arms}) >= 2  # the crank's arms on layers of their own
    assert all(0 in p["joints"] for p in arms)  # a star on the motor's shaft
    assert parts["pin_0"]["fixed_in"] == CRANK
    lo, hi = parts["pin_0"]["layers"]
    assert all(lo <= p["layer"] <= hi for p in arms)  # the shaft holds every arm
    for p in arms:
        assert trimesh.load(out / p["mesh"]).is_watertight


def test_a_strap_moved_onto_a_pin_its_sheave_lets_through_is_caught(built, tmp_path):
    """Link 2-7's strap, round a sheave of the crank at 2, shifted onto the motor's shaft."""
    out, result, _ = built
    detail = strap_moved_onto(SPLIT_STRAPPED, out, result, tmp_path, "link_2_7", 2, 0)
    assert "pin_0" in detail and "link_2_7_piece" in detail


def test_an_arm_made_a_strap_is_built_verified_and_checked(tmp_path):
    """Built and verified; its strap, shifted onto the motor's shaft, is caught."""
    out, planted = tmp_path / "built", tmp_path / "planted"
    out.mkdir(), planted.mkdir()
    result, report = export_verified(ARM_STRAPPED, out, {"mjcf", "stl"})
    assert report.passed, report.failed
    parts = {p["name"]: p for p in json.loads((out / "mechanism.json").read_text())["parts"]}
    arm, sheave = parts[ARM], parts[f"{ARM}_sheave"]
    assert arm["arm_of"] == "plate_1_4_8_9" and arm["joints"] == [1, 4]  # bored round joint 1
    assert sheave["fixed_in"] == "plate_0_1_2_7" and sheave["joints"] == [1, 0]
    sheaves = [n for n, p in parts.items() if p["kind"] == "sheave"]
    assert sheaves_crossed(ARM_STRAPPED, out, parts, sheaves)
    lo, hi = parts["pin_0"]["layers"]
    assert lo <= arm["layer"] <= hi  # the motor's shaft crosses the arm's layer in its sheave
    detail = strap_moved_onto(ARM_STRAPPED, out, result, planted, ARM, 1, 0)
    assert "pin_0" in detail and f"{ARM}_piece" in detail
