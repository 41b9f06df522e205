"""Ground pins held from both plates (linkd.export.layers): a mechanism no whole ground pin lets
layer (with the strap it needs) is built with a pin in the base and a stub from the cover,
verified, and a stub moved onto a passing part's layer is caught."""

import pytest
import trimesh
from planted import collision_detail, editable_copy

from linkd.export import export_mechanism
from linkd.mechanism import Mechanism
from linkd.verify import verify_output

# linkd's generator, `generate(200, 3, GeneratorSettings(7, 13)).graphs[80]` at 100 mm
STUBBED = Mechanism(
    [(-31.154, 60.579), (-16.512, 80.761), (95.471, -34.78), (39.237, 39.04), (-84.238, -33.977),
     (-45.927, -51.68), (-69.963, 63.462), (7.227, -5.818), (10.95, 74.203), (-98.43, 90.852),
     (-71.931, 55.216), (-80.13, -12.036)],
    [1, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0],
    [(0, 1), (0, 2), (0, 8), (1, 2), (1, 4), (1, 6), (1, 10), (3, 4), (3, 5), (4, 5), (4, 7),
     (4, 8), (5, 6), (5, 7), (6, 9), (8, 9), (8, 11), (9, 10), (9, 11)],
    (0, 1), 11,
)  # fmt: skip


@pytest.fixture(scope="module")
def split_ground(tmp_path_factory):
    out = tmp_path_factory.mktemp("split_ground")
    return out, export_mechanism(STUBBED, out, {"mjcf", "stl"})


def test_the_two_stubs_are_built_and_verified(split_ground):
    out, result = split_ground
    parts = {p["name"]: p for p in result.parts}
    assert not any("arm_of" in p or p["kind"] == "post" for p in result.parts)
    base, stub = parts["pin_0"], parts["pin_0_top"]
    cover = parts["ground_cover"]
    assert base["layers"][0] == 0 and stub["layers"][1] == cover["layer"] == result.layers - 1
    assert base["joins"] == ["ground", "plate_0_1_2"] and stub["joins"] == [
        "ground_cover",
        "link_0_8",
    ]
    assert 0 in parts["ground"]["joints"] and 0 in cover["joints"]
    for name in ("pin_0", "pin_0_top"):  # each stub reaches exactly the plates it joins
        layers = [parts[j]["layer"] for j in parts[name]["joins"] if j != "ground"]
        ground = 0 if name == "pin_0" else cover["layer"]
        assert parts[name]["layers"] == [min(*layers, ground), max(*layers, ground)]
    for part in result.parts:
        if "mesh" in part:
            solid = trimesh.load(out / part["mesh"])
            assert solid.is_watertight and solid.is_volume
    report = verify_output(out, write=False)
    assert report.passed, report.failed


def test_a_stub_lowered_onto_a_passing_part_is_caught(split_ground, tmp_path):
    """The cover's stub at joint 0 moved down to the layer of link_1_10, which passes over the
    joint between the two stubs: verification must name the stub."""
    tree, geoms = editable_copy(split_ground[0], tmp_path)
    stub, passing = geoms["pin_0_top"], geoms["link_1_10"]
    x, y, _ = stub.get("pos").split()
    stub.set("pos", f"{x} {y} {passing.get('pos').split()[2]}")
    assert "pin_0_top" in collision_detail(tree, tmp_path)
