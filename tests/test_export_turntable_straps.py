"""Straps beside a turntable (linkd.export.turntable with linkd.export.strapped): the crank a
disc on its own layer, and two links made straps round sheaves, so pins cross the straps'
layers. Neither construction builds the mechanism alone; together they do, verified in
MuJoCo, and a strap planted over a pin its sheave lets through is caught. Where one strap or
two beside the turntable do not do, more round a core may (tried last of all): four build
another mechanism."""

import json

import pytest
import trimesh
from test_export_strapped import sheaves_crossed, strap_moved_onto

from linkd.export.layers import NoFlatLayers, sweep
from linkd.export.options import ExportOptions, resolve_sizes
from linkd.export.parts import assemble
from linkd.export.strapped import strapped_layers
from linkd.mechanism import Mechanism
from linkd.verified import export_verified

# Generated (seed 7, no. 85 of 100), in mm. The parts passing over the motor's pivot lie on
# both sides of the crank plate in every order, and links 4-15 and 9-12 sweep over pins 1 and
# 3, 6 of the parts they turn on. With the crank on a turntable and those two links straps
# round sheaves that hold those pins, it layers, at half the usual width.
TABLE_STRAPPED = Mechanism(
    [(99.336, -36.62), (74.653, -53.423), (-32.833, 30.265), (-20.298, -82.415), (65.53, 5.702),
     (-87.699, 95.401), (-18.865, 25.43), (-6.001, 95.663), (-47.25, 71.406), (51.121, 73.88),
     (4.921, -71.409), (26.216, 98.698), (-83.304, -88.488), (76.802, 65.37), (85.343, 44.272),
     (-98.037, -53.487), (-56.539, -40.5), (-10.527, -33.237)],
    [1, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0],
    [(0, 1), (0, 2), (0, 5), (1, 2), (1, 4), (1, 7), (1, 8), (1, 10), (1, 11), (2, 5), (2, 14),
     (3, 4), (4, 15), (5, 8), (5, 12), (5, 16), (6, 7), (6, 11), (8, 13), (8, 15), (9, 10),
     (9, 12), (10, 13), (12, 14), (12, 17), (14, 16), (15, 17)],
    (0, 1), 17, units="mm",
)  # fmt: skip
CRANK = "plate_0_1_2_5_8"
SHEAVES = {"link_4_15_sheave": "link_1_4", "link_9_12_sheave": "ground"}  # -> fixed in

# Generated (seed 31, no. 19 of 100), in mm: with the crank plate on a turntable, no one or two
# straps layer it; four, round a core of straps, do.
FOUR_STRAPS = Mechanism(
    [(95.842, 79.033), (77.251, 35.366), (-53.841, 43.25), (37.114, 38.516), (-19.896, -82.098),
     (46.893, 15.948), (33.507, 82.849), (41.761, -79.81), (2.969, 95.718), (-76.038, 10.556),
     (-2.394, -31.361), (-29.782, 69.437), (-87.845, -71.437), (73.606, -49.776),
     (-36.029, -6.245), (-41.227, -90.274), (40.767, -24.924)],
    [1, 0, 0, 1, 0, 1, 0, 0, 1, 0, 0, 1, 0, 1, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 6), (1, 10), (1, 14), (1, 15), (2, 4), (2, 7), (2, 16), (3, 4),
     (5, 6), (6, 7), (6, 10), (7, 9), (8, 9), (9, 12), (11, 12), (11, 15), (12, 16), (13, 14)],
    (0, 1), 16, units="mm",
)  # fmt: skip
FOUR_SHEAVES = {"link_3_4_sheave": "ground", "link_8_9_sheave": "ground",
                "link_11_12_sheave": "ground", "link_1_15_sheave": "plate_0_1_2"}  # fmt: skip


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("table_strapped")
    result, report = export_verified(TABLE_STRAPPED, out, {"mjcf", "stl"})
    return out, result, report


@pytest.mark.parametrize("fraction", [1.0, 0.5, 0.25])
def test_straps_alone_do_not_build_it(fraction):
    assembly = assemble(TABLE_STRAPPED)
    usual = resolve_sizes(TABLE_STRAPPED, assembly.parts, None).link_width
    narrow = ExportOptions(link_width=usual * fraction)
    sizes = resolve_sizes(TABLE_STRAPPED, assembly.parts, narrow)
    with pytest.raises(NoFlatLayers):
        strapped_layers(assembly, sweep(TABLE_STRAPPED, sizes.link_width), sizes)


def test_straps_beside_the_turntable_are_built_and_verified(built):
    out, result, report = built
    assert report.passed, report.failed
    assert result.turntable == CRANK
    parts = {p["name"]: p for p in json.loads((out / "mechanism.json").read_text())["parts"]}
    assert {n: p["fixed_in"] for n, p in parts.items() if p["kind"] == "sheave"} == SHEAVES
    assert sheaves_crossed(TABLE_STRAPPED, out, parts, SHEAVES)  # some pins cross through
    pins = {p["name"]: p for p in parts.values() if p["kind"] == "pin"}
    layer = parts[CRANK]["layer"]
    spans = {n: p["layers"] for n, p in pins.items() if CRANK not in p["joins"]}
    foreign = [n for n, (lo, hi) in spans.items() if lo <= layer <= hi]
    assert not foreign  # only the crank's own pins cross the disc's layer
    assert not [p for p in pins.values() if p["joints"] == [0]]  # no shaft at the motor's pivot
    for name in (CRANK, "ground_ring"):
        assert trimesh.load(out / parts[name]["mesh"]).is_watertight


def test_a_strap_moved_onto_a_pin_its_sheave_lets_through_is_caught(built, tmp_path):
    """Link 4-15's strap, round a sheave of link 1-4 at 4, shifted onto pin 1 in it."""
    out, result, _ = built
    detail = strap_moved_onto(TABLE_STRAPPED, out, result, tmp_path, "link_4_15", 4, 1)
    assert "pin_1" in detail and "link_4_15_piece" in detail


def test_four_straps_round_a_core_beside_the_turntable_are_built_and_verified(tmp_path):
    result, report = export_verified(FOUR_STRAPS, tmp_path, {"mjcf", "stl"})
    assert report.passed, report.failed
    assert result.turntable == "plate_0_1_2"
    parts = {p["name"]: p for p in json.loads((tmp_path / "mechanism.json").read_text())["parts"]}
    assert {n: p["fixed_in"] for n, p in parts.items() if p["kind"] == "sheave"} == FOUR_SHEAVES
    assert sheaves_crossed(FOUR_STRAPS, tmp_path, parts, FOUR_SHEAVES)
