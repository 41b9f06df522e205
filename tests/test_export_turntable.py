"""The crank on a turntable (linkd.export.turntable): a disc turning in a ground ring, with no
pin at the motor's pivot, builds a mechanism that every other construction refuses; verified
in MuJoCo, and planted collisions of the ring and of a pin through the disc are caught."""

import json

import numpy as np
import pytest
import trimesh
from planted import collision_detail, editable_copy
from test_export_narrow import SNARLED

from linkd.export.forked import forked_layers
from linkd.export.layers import sweep
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.mechanism import Mechanism
from linkd.verified import export_verified

# Generated (seed 2026, no. 29 of 200), in mm. The crank is a plate of seven joints, and the
# parts passing over its pivot lie on both sides of it in every order the other pins allow, so
# no shaft from the base or the cover reaches it, forked or not. On a turntable its layer
# splits the stack: link 0-8 turns on a stub from the base below it.
TURNTABLE = Mechanism(
    [(95.166, 10.597), (90.665, 47.985), (-73.505, 86.045), (68.604, -7.027), (63.747, -71.198),
     (-41.934, 40.616), (33.835, -91.448), (62.453, -36.148), (45.93, 36.3), (10.147, 33.637),
     (-78.702, -98.774), (26.986, 68.89), (-82.106, 33.479), (-18.533, -66.791),
     (74.509, -69.574), (-85.977, -52.217)],
    [1, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0],
    [(0, 1), (0, 4), (0, 5), (0, 8), (1, 3), (1, 4), (1, 5), (1, 6), (1, 7), (1, 9), (2, 3),
     (3, 8), (3, 9), (5, 6), (5, 10), (5, 15), (6, 7), (6, 10), (8, 11), (9, 11), (10, 14),
     (11, 13), (11, 14), (11, 15), (12, 13)],
    (0, 1), 15, units="mm",
)  # fmt: skip
CRANK = "plate_0_1_4_5_6_7_10"


@pytest.fixture(scope="module")
def turntable(tmp_path_factory):
    out = tmp_path_factory.mktemp("turntable")
    result, report = export_verified(TURNTABLE, out, {"mjcf", "stl"})
    return out, result, report


def test_the_last_construction_before_it_refuses_the_mechanism():
    assembly = assemble(TURNTABLE)
    sizes = resolve_sizes(TURNTABLE, assembly.parts, None)
    with pytest.raises(ValueError):
        forked_layers(assembly, sweep(TURNTABLE, sizes.link_width), sizes)


def test_the_crank_on_a_turntable_is_built_and_verified(turntable):
    out, result, report = turntable
    assert report.passed, report.failed
    parts = {p["name"]: p for p in json.loads((out / "mechanism.json").read_text())["parts"]}
    crank, ring = parts[CRANK], parts["ground_ring"]
    assert crank["layer"] == ring["layer"]
    sizes = result.sizes
    assert ring["bore"] == pytest.approx(crank["disc"] + 2 * sizes["clearance"])
    positions = TURNTABLE.positions
    reach = np.linalg.norm(positions[crank["joints"]] - positions[0], axis=1).max()
    assert crank["disc"] / 2 == pytest.approx(reach + sizes["link_width"] / 2)
    for name in (CRANK, "ground_ring"):  # the disc and the ring are watertight solids
        assert trimesh.load(out / parts[name]["mesh"]).is_watertight
    pins = [p for p in parts.values() if p["kind"] == "pin"]
    assert not [p for p in pins if 0 in p["joints"] and CRANK in p["joins"]]  # no shaft
    assert [p["joins"] for p in pins if p["joints"] == [0]] == [["ground", "link_0_8"]]
    layer = crank["layer"]
    crossing = [p["name"] for p in pins if p["layers"][0] <= layer <= p["layers"][1]
                and CRANK not in p["joins"]]  # fmt: skip
    assert not crossing  # only the crank's own pins cross its layer
    posts = [p for p in parts.values() if p["kind"] == "post"]
    assert len(posts) == 3 and all(p["layers"] == [0, layer] for p in posts)
    assert sorted(map(tuple, ring["posts"])) == sorted(tuple(p["at"]) for p in posts)


@pytest.mark.parametrize("plant", ["ground_ring_piece0", "pin_0"])
def test_a_planted_collision_on_the_turntable_is_caught(turntable, tmp_path, plant):
    """The ring's first piece moved in across the gap onto the disc; the stub at the motor's
    pivot moved up into the disc's layer."""
    out, result, _ = turntable
    tree, geoms = editable_copy(out, tmp_path)
    sizes, unit = result.sizes, 1e-3  # mm
    if plant == "pin_0":
        layer = next(p["layer"] for p in result.parts if p["name"] == CRANK)
        z = (layer * (sizes["thickness"] + sizes["layer_gap"]) + sizes["thickness"] / 2) * unit
        radius = geoms[plant].get("size").split()[0]
        geoms[plant].set("size", f"{radius} {sizes['thickness'] / 2 * unit}")
        geoms[plant].set("pos", f"0 0 {z}")
    else:  # the piece's corner at angle 0 moved in by three times the gap
        _, _, z = geoms[plant].get("pos").split()
        geoms[plant].set("pos", f"{-3 * sizes['clearance'] * unit} 0 {z}")
    detail = collision_detail(tree, tmp_path)
    assert plant in detail and CRANK in detail


def test_three_couplers_on_the_crank_tip_are_built_on_a_turntable(tmp_path, capsys):
    """SNARLED: links 1-3, 1-4 and 1-7 on the tip of the crank plate sweep over the ground
    pivots and each other's pins; the crank alone turns at the motor's pivot, which then has no
    pin at all. `linkd export` tells the builder: no shaft there, the motor drives the rim."""
    from linkd.cli import main

    path, out = tmp_path / "snarled.json", tmp_path / "out"
    SNARLED.save(path)
    assert main(["export", str(path), "--out", str(out), "--export", "mjcf"]) == 0  # verified
    assert "the crank (plate_0_1_4) on a turntable: drive it at its rim" in capsys.readouterr().out
    parts = {p["name"]: p for p in json.loads((out / "mechanism.json").read_text())["parts"]}
    assert "disc" in parts["plate_0_1_4"] and "bore" in parts["ground_ring"]
    assert not [p for p in parts.values() if p["kind"] == "pin" and p["joints"] == [0]]
