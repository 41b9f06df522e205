"""Forked parts (linkd.export.forked): a part made as one arm per part it carries, each
turning on a rod of its own, builds mechanisms that no flat, bent, split or bracketed layering
does; verified in MuJoCo, and a planted collision of a rod is caught."""

from itertools import pairwise

import pytest
import trimesh
from planted import collision_detail, editable_copy

import linkd.export.braced as braced
import linkd.export.forked as forked
import linkd.export.forked_rings as forked_rings
import linkd.export.ground_rings as ground_rings
import linkd.export.turntable as turntable
from linkd.export import export_mechanism
from linkd.export.layers import NoFlatLayers
from linkd.export.parts import assemble
from linkd.mechanism import Mechanism
from linkd.verified import export_verified

pytestmark = pytest.mark.usefixtures("straps_and_frames_off")  # built otherwise with those

# Generated (seed 2026, no. 93 of 200). The crank plate 0-1-2 carries plate 2-4-7 and link
# 2-6 at joint 2, and they sweep over the ground pivots 0, 3 and 5, so pivot 0 must be held from
# inside the stack; yet the pin at 2 circles it, crossing any bracket's arm. Forked like a
# bicycle's crank, an arm to joint 2 for each part there, the bracket holds the shaft at 0
# between them and the two rods at 2 stop short of its layer.
BICYCLE = Mechanism(
    [(37.863, -21.143), (25.234, -48.106), (-86.007, -23.147), (-17.77, 51.125),
     (65.951, -66.945), (71.221, -48.346), (-26.21, 77.166), (80.284, 6.249)],
    [1, 0, 0, 1, 0, 1, 0, 0],
    [(0, 1), (0, 2), (1, 2), (2, 4), (2, 6), (2, 7), (3, 4), (4, 7), (5, 6)],
    (0, 1), 7,
)  # fmt: skip

# Generated (seed 2026, no. 195 of 200): link 4-8 carries link 3-4 and plate 1-4-5 at joint 4.
# Forked at joint 8 into two arms, a clevis with links 7-8 and 8-9 turning between them, each
# arm carrying one of the two at joint 4; no bracket needed.
CLEVIS = Mechanism(
    [(-81.784, -90.473), (-60.897, -93.466), (8.016, 7.134), (-80.101, 95.245), (-0.56, -32.591),
     (93.183, -81.295), (-24.178, 16.897), (0.035, 62.547), (-30.307, -78.564), (68.217, 74.335)],
    [1, 0, 0, 1, 0, 0, 0, 1, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 4), (1, 5), (1, 6), (2, 6), (3, 4), (4, 5), (4, 8), (6, 9),
     (7, 8), (8, 9)],
    (0, 1), 9,
)  # fmt: skip

# The best design `linkd design` found for LInK-Bench's drawn Q (seed 0), in mm. Link 0-5 turns
# on the motor pivot beside the crank; forking it at 5 would hang the crank on a rod of its own.
TWIN = Mechanism(
    [(-4.732, -3.2465), (-3.1071, -4.127), (-4.422, -4.0992), (-4.0024, -2.1654),
     (-3.9567, -3.7518), (-2.1545, -2.3155), (-3.581, -5.1577), (0.1042, -1.3971),
     (-4.662, 1.8155), (-0.1069, -0.4883)],
    [1, 0, 1, 0, 0, 0, 0, 1, 0, 0],
    [(0, 1), (0, 5), (1, 3), (1, 4), (2, 3), (2, 6), (3, 4), (3, 5), (4, 6), (5, 8), (6, 9),
     (7, 8), (8, 9)],
    (0, 1), 9, units="mm",
)  # fmt: skip


@pytest.fixture(scope="module")
def bicycle(tmp_path_factory):
    out = tmp_path_factory.mktemp("bicycle")
    result, report = export_verified(BICYCLE, out, {"mjcf", "stl"})
    return out, result, report


def _forked_parts(out, parts: list[dict]) -> tuple[str, dict[int, list[dict]]]:
    """The forked part and its rods by joint, after checking the build: every plate a watertight
    solid; every arm of the part from one shaft joint; each rod fixed in the part, running from
    an arm of it to the parts turning on it (holes at both ends), the rods at a joint apart."""
    for part in parts:
        if "mesh" in part:
            solid = trimesh.load(out / part["mesh"])
            assert solid.is_watertight and solid.is_volume
    arms = [p for p in parts if "arm_of" in p]
    name = arms[0]["arm_of"]
    assert {p["arm_of"] for p in arms} == {name}
    shared = set.intersection(*(set(p["joints"]) for p in arms))
    rods: dict[int, list[dict]] = {}
    for pin in (p for p in parts if p["kind"] == "pin" and p["name"][-1].isalpha()):
        joint = pin["joints"][0]
        assert pin["fixed_in"] == name == pin["joins"][0]
        at = {p["name"]: p["layer"] for p in parts if "layer" in p and joint in p["joints"]}
        mine = [at[p["name"]] for p in arms if joint in p["joints"]]
        theirs = [at[other] for other in pin["joins"][1:]]
        lo, hi = pin["layers"]
        assert {lo, hi} <= {*mine, *theirs} and all(lo <= layer <= hi for layer in theirs)
        assert any(lo <= layer <= hi for layer in mine)
        rods.setdefault(joint, []).append(pin)
    assert len(shared - set(rods)) == 1  # the shaft
    for cut in rods.values():
        spans = sorted(pin["layers"] for pin in cut)
        assert len(cut) >= 2 and all(a[1] < b[0] for a, b in pairwise(spans))
    return name, rods


def test_a_crank_walled_in_by_its_pins_is_forked_round_a_bracket(bicycle, monkeypatch, tmp_path):
    def refused(*args, **kwargs):
        raise NoFlatLayers("not on a turntable either")

    monkeypatch.setattr(forked, "MAX_FORKS", 0)
    monkeypatch.setattr(forked, "MAX_SETS", 0)
    monkeypatch.setattr(turntable, "stack_layers", refused)  # its whole parts layer it too
    with pytest.raises(ValueError, match="flat layers"):
        export_mechanism(BICYCLE, tmp_path, {"mjcf"})
    out, result, report = bicycle
    assert report.passed, report.failed
    name, rods = _forked_parts(out, result.parts)
    assert name == "plate_0_1_2" and list(rods) == [2]
    parts = {p["name"]: p for p in result.parts}
    bracket, shaft = parts["ground_bracket0"], parts["pin_0"]
    assert bracket["joints"] == [0] and shaft["fixed_in"] == name
    assert shaft["joins"] == ["ground_bracket0", name]  # the bracket it turns in, not the base
    low, high = sorted(rods[2], key=lambda pin: pin["layers"])
    assert shaft["layers"][0] < bracket["layer"] < shaft["layers"][1]
    assert low["layers"][1] < bracket["layer"] < high["layers"][0]  # the rods stop short of it


def test_a_link_carrying_two_parts_at_one_joint_is_forked_without_a_bracket(monkeypatch, tmp_path):
    monkeypatch.setattr(forked, "MAX_FORKS", 0)
    monkeypatch.setattr(forked, "MAX_SETS", 0)
    monkeypatch.setattr(braced, "MAX_CUT_SCREENED", 0)  # the crank cut in two builds it too
    monkeypatch.setattr(ground_rings, "MAX_SPLITS", 0)  # and so do ground rings
    monkeypatch.setattr(forked_rings, "MAX_RINGED", 0)  # alone or beside forks
    with pytest.raises(ValueError, match="flat layers"):
        export_mechanism(CLEVIS, tmp_path / "refused", {"mjcf"})
    monkeypatch.undo()
    result, report = export_verified(CLEVIS, tmp_path, {"mjcf", "stl"})
    assert report.passed, report.failed
    name, rods = _forked_parts(tmp_path, result.parts)
    assert name == "link_4_8" and list(rods) == [4]
    parts = {p["name"]: p for p in result.parts}
    arms = sorted(p["layer"] for p in result.parts if p.get("arm_of") == name)
    assert parts["pin_8"]["layers"] == arms and parts["pin_8"]["fixed_in"] == name
    assert all(arms[0] < parts[link]["layer"] < arms[1] for link in ("link_7_8", "link_8_9"))
    assert not any(p["kind"] == "post" for p in result.parts)


def test_a_rod_lengthened_into_the_bracket_is_caught(bicycle, tmp_path):
    """The upper rod at joint 2 stood down onto the bracket's layer: the bracket's arm crosses
    the joint's circle, so verification must name the rod."""
    tree, geoms = editable_copy(bicycle[0], tmp_path)
    rod, bracket = geoms["pin_2b"], geoms["ground_bracket0"]
    radius, half = map(float, rod.get("size").split())
    x, y, z = map(float, rod.get("pos").split())
    floor = float(bracket.get("pos").split()[2])
    top = z + half
    rod.set("size", f"{radius} {(top - floor) / 2}")
    rod.set("pos", f"{x} {y} {(top + floor) / 2}")
    detail = collision_detail(tree, tmp_path)
    assert "pin_2b" in detail


def test_no_fork_hangs_the_crank_on_another_parts_rod():
    """A fork cuts every pin of its part but the shaft's. Cut at the motor pivot for another
    part, the crank would turn on a rod of that part, which a motor in the frame cannot drive;
    the crank's own fork may cut it (its rod there still turns in the frame)."""
    assembly = assemble(TWIN)
    number = {part.name: q for q, part in enumerate(assembly.parts)}
    link, crank = number["link_0_5"], number["link_0_1"]
    assert not forked.drivable(assembly, (link, 5))
    assert forked.drivable(assembly, (link, 0))  # its shaft at the pivot: the pin stays whole
    assert forked.drivable(assembly, (crank, 1))


def test_coaxial_rods_that_would_meet_are_made_one():
    """Rods at one joint sharing a layer would be one piece of metal: one rod through the parts
    of both; rods apart stay apart, bottom up."""
    apart = [((4,), (5, 6)), ((3,), (1, 3))]
    assert forked._merged(apart) == (((3,), (1, 3)), ((4,), (5, 6)))
    meeting = [((5,), (5, 7)), ((3,), (1, 3)), ((4,), (3, 5))]
    assert forked._merged(meeting) == (((3, 4, 5), (1, 7)),)
