"""Split plates and ground brackets (linkd.export.braced): mechanisms that neither straight nor
bent links can layer, built and verified, and planted collisions of arms, shafts, brackets and
posts caught."""

import xml.etree.ElementTree as ET

import mujoco
import pytest
import trimesh
from planted import collision_detail, editable_copy
from test_export_narrow import KNOTTED

from linkd.export import ExportOptions, buildable, export_mechanism
from linkd.export.layers import assign_layers, sweep
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.export.routing import bent_layers
from linkd.mechanism import Mechanism
from linkd.verify import verify_output

pytestmark = pytest.mark.usefixtures("straps_and_frames_off")  # built otherwise with those

# Generated (seed 2026, no. 90 of 200): refused before plates other than the crank could split.
# Its five-joint plate splits on a shaft at joint 8, which no other part shares, and ground
# pin 11 is held by a bracket.
STACKED = Mechanism(
    [(-93.225, -89.054), (-68.702, -86.843), (71.998, -89.146), (-73.228, -34.543),
     (-45.291, 33.477), (-93.772, 34.618), (-16.545, 71.46), (37.706, 32.481), (91.049, 61.354),
     (-3.935, 46.712), (75.502, -8.088), (-42.077, 13.98), (-95.68, 97.344), (-88.157, 41.722),
     (76.274, 20.497), (88.373, -36.959), (31.151, -91.223), (-18.075, -22.546)],
    [1, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 0, 0, 0, 0],
    [(0, 1), (0, 4), (0, 9), (0, 16), (1, 3), (1, 4), (1, 7), (1, 14), (2, 3), (2, 5), (2, 8),
     (2, 10), (3, 5), (3, 8), (3, 15), (4, 15), (5, 9), (5, 10), (5, 12), (6, 7), (7, 17),
     (9, 16), (9, 17), (11, 12), (13, 14)],
    (0, 1), 17,
)  # fmt: skip


@pytest.fixture(scope="module")
def knotted(tmp_path_factory):
    out = tmp_path_factory.mktemp("knotted")
    return out, export_mechanism(KNOTTED, out, {"mjcf", "stl"})


@pytest.fixture(scope="module")
def stacked(tmp_path_factory):
    """STACKED exported with meshes, and (its layers searched once) as MJCF alone."""
    import linkd.export

    layered, found = linkd.export._layered, []

    def once(*args, **kwargs):
        if not found:
            found.append(layered(*args, **kwargs))
        return found[0]

    out, bare = tmp_path_factory.mktemp("stacked"), tmp_path_factory.mktemp("bare")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(linkd.export, "_layered", once)
        result = export_mechanism(STACKED, out, {"mjcf", "stl"})
        export_mechanism(STACKED, bare, {"mjcf"})
    return out, result, bare


def _refused_flat_and_bent(mech: Mechanism) -> None:
    assembly = assemble(mech)
    sizes = resolve_sizes(mech, assembly.parts, None)
    paths = sweep(mech, sizes.link_width)
    for layering in (assign_layers, bent_layers):
        with pytest.raises(ValueError, match="flat layers"):
            layering(assembly, paths, sizes)


def _check_parts(out, parts: list[dict]) -> None:
    """Every plate a watertight solid; every pin reaches exactly the plates with its hole; the
    arms of a split part are a tree over its joints, and the pins where arms meet are fixed in
    the part (so they turn as one)."""
    for part in parts:
        if "mesh" in part:
            solid = trimesh.load(out / part["mesh"])
            assert solid.is_watertight and solid.is_volume
        if part["kind"] == "pin":
            lo, hi = part["layers"]
            holes = [p["layer"] for p in parts if "layer" in p and p["kind"] != "pin"
                     and part["joints"][0] in p["joints"]]  # fmt: skip
            assert min(holes) == lo and max(holes) == hi
    split = {p["arm_of"] for p in parts if "arm_of" in p}
    assert split
    for name in split:
        arms = [p["joints"] for p in parts if p.get("arm_of") == name]
        joints = {int(j) for j in name.split("_")[1:]}
        reached = set(arms[0])
        while any(set(arm) & reached and not set(arm) <= reached for arm in arms):
            reached |= set(next(a for a in arms if set(a) & reached and not set(a) <= reached))
        assert len(arms) == len(joints) - 1 and reached == joints
        meet = {j for j in joints if sum(j in arm for arm in arms) >= 2}
        pins = {p["joints"][0]: p.get("fixed_in") for p in parts if p["kind"] == "pin"}
        assert meet and all(pins[j] == name for j in meet)


def test_a_crank_refused_flat_and_bent_is_built_split_and_verified(knotted):
    out, result = knotted
    _refused_flat_and_bent(KNOTTED)
    _check_parts(out, result.parts)
    assert {p["arm_of"] for p in result.parts if "arm_of" in p} == {"plate_0_1_2"}
    assert verify_output(out, write=False).passed


def test_a_plate_split_on_its_own_shaft_and_a_bracketed_pin_are_built_and_verified(stacked):
    out, result, _ = stacked
    _refused_flat_and_bent(STACKED)
    _check_parts(out, result.parts)
    parts = {p["name"]: p for p in result.parts}
    shaft = parts["pin_8"]  # joint 8 is on the plate alone: the shaft is the plate's own pin
    assert shaft["joins"] == ["plate_2_3_5_8_10"] == [shaft["fixed_in"]]
    bracket, post = parts["ground_bracket0"], parts["ground_post0"]
    assert bracket["joints"] == [11] and bracket["posts"] == [post["at"]]
    assert bracket["layer"] in post["layers"] and bracket["layer"] in parts["pin_11"]["layers"]
    report = verify_output(out, write=False)
    assert report.passed, report.failed


def _moved(geom: ET.Element, z: float | None = None, xy: tuple | None = None) -> None:
    x, y, height = map(float, geom.get("pos").split())
    x, y = xy or (x, y)
    geom.set("pos", f"{x} {y} {height if z is None else z}")


@pytest.mark.parametrize("plant", ["arm", "shaft", "bracket", "post"])
def test_a_planted_collision_in_a_split_plate_or_a_bracket_is_caught(stacked, tmp_path, plant):
    """An arm laid on the layer of a link it shares a joint with, the shaft moved onto another
    joint, the bracket laid on its link's layer, or the post set down across that link:
    verification must name the part."""
    tree, geoms = editable_copy(stacked[0], tmp_path)

    def z(name: str) -> float:
        return float(geoms[name].get("pos").split()[2])

    if plant == "arm":  # the arm to joint 3 onto link_3_15's layer: their bosses overlap
        name = "plate_2_3_5_8_10_arm1"
        _moved(geoms[name], z=z("link_3_15"))
    elif plant == "shaft":  # the shaft, layers 1..16, stood at joint 5 through link_5_12
        name = "pin_8"
        x, y = (STACKED.positions[5] - STACKED.positions[8]) * 1e-3  # in the pin's body frame
        _moved(geoms[name], xy=(x, y))
    elif plant == "bracket":
        name = "ground_bracket0"
        _moved(geoms[name], z=z("link_11_12"))
    else:  # the post, layers 0..5, at the middle of link_11_12 (layer 4)
        name = "ground_post0"
        middle = STACKED.positions[[11, 12]].mean(0)
        x, y = (middle - STACKED.positions[STACKED.motor[0]]) * 1e-3  # the ground's frame
        _moved(geoms[name], xy=(x, y))
    assert name in collision_detail(tree, tmp_path)


def test_without_brackets_the_same_mechanism_is_refused(tmp_path):
    """What a design run past its time budget asks for: the slow construction left out."""
    assert buildable(KNOTTED)
    assert not buildable(KNOTTED, ExportOptions(brackets=False))
    with pytest.raises(ValueError, match="flat layers"):
        export_mechanism(KNOTTED, tmp_path, {"mjcf"}, ExportOptions(brackets=False))


def test_a_bracketed_model_without_meshes_compiles(stacked):
    """Without STL the plates are boxes and discs: the disc round a post in the base plate is
    named apart from the post itself (MuJoCo refuses a repeated geom name)."""
    bare = stacked[2]
    assert not (bare / "meshes").exists()
    assert any(p["kind"] == "post" for p in Mechanism.load(bare / "mechanism.json").extra["parts"])
    names = [g.get("name") for g in ET.parse(bare / "mechanism.xml").iter("geom")]
    assert mujoco.MjModel.from_xml_path(str(bare / "mechanism.xml")).ngeom > 0
    assert "ground_post0" in names and len(names) == len(set(names))
