"""Eccentric straps (linkd.export.strapped): a link that turns about a joint of another part,
made as a strap round a sheave of that part, lets the part's other pins cross its layer through
the sheave. It builds mechanisms that no flat layering does, verified in MuJoCo with and without
meshes, and a strap planted over the pin its sheave carries through is caught."""

import numpy as np
import pytest
import trimesh
from planted import collision_detail, editable_copy

from linkd.export.layers import NoFlatLayers, assign_layers, sweep
from linkd.export.meshes import strap_meshes
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.export.strapped import strapped_layers
from linkd.mechanism import UNITS_IN_METRES, Mechanism
from linkd.verified import export_verified

# Generated (seed 2026, no. 160 of 200), refused by every construction before straps: link 3-4
# turns about ground pivot 3 and sweeps over ground pivot 7, whose pin must then come from the
# side of the stack that other parts wall in. As a strap round a ground sheave at 3, wide
# enough to hold pivot 7, pin 7 passes through its layer.
STRAPPED = Mechanism(
    [(32.712, -80.538), (49.047, -86.4), (60.565, -11.386), (19.133, -67.935), (-99.915, 37.983),
     (-37.031, -72.358), (-38.665, 52.526), (4.221, -84.64), (46.391, -32.592), (-53.607, 88.962),
     (9.743, 67.888), (11.217, -37.811)],
    [1, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 5), (1, 11), (2, 4), (2, 5), (2, 6), (3, 4), (4, 6), (4, 11),
     (5, 9), (5, 10), (6, 8), (7, 8), (8, 9), (9, 10)],
    (0, 1), 11,
)  # fmt: skip


@pytest.fixture(scope="module")
def strapped(tmp_path_factory):
    out = tmp_path_factory.mktemp("strapped")
    result, report = export_verified(STRAPPED, out, {"mjcf", "stl"})
    return out, result, report


def test_a_mechanism_no_flat_layering_builds_is_strapped_and_verified(strapped):
    assembly = assemble(STRAPPED)
    sizes = resolve_sizes(STRAPPED, assembly.parts, None)
    with pytest.raises(NoFlatLayers):
        assign_layers(assembly, sweep(STRAPPED, sizes.link_width), sizes)
    layout = strapped_layers(assembly, sweep(STRAPPED, sizes.link_width), sizes)
    assert [(assembly.parts[s.part].name, s.joint, s.sheave_of) for s in layout.straps] == [
        ("link_3_4", 3, 0)
    ]
    out, result, report = strapped
    assert report.passed, report.failed
    parts = {p["name"]: p for p in result.parts}
    strap, sheave, pin = parts["link_3_4"], parts["link_3_4_sheave"], parts["pin_7"]
    assert sheave["kind"] == "sheave" and sheave["fixed_in"] == "ground"
    assert sheave["layer"] == strap["layer"] and sheave["diameter"] == strap["bore"]
    assert sheave["joints"] == [3, 7] and parts["pin_3"]["fixed_in"] == "ground"
    assert pin["layers"][0] <= strap["layer"] <= pin["layers"][1]  # it crosses the strap's layer
    gap = strap["bore"] / 2 - np.linalg.norm(STRAPPED.positions[7] - STRAPPED.positions[3])
    assert gap >= pin["diameter"] / 2  # ... inside the sheave, clear of the strap
    for path in [strap["mesh"], sheave["mesh"], *strap["pieces"]]:
        assert trimesh.load(out / path).is_watertight


def test_a_strap_without_meshes_is_verified_too(tmp_path):
    """Without STL the strap's ring is boxes round the bore: MuJoCo proves the same."""
    _, report = export_verified(STRAPPED, tmp_path, {"mjcf"})
    assert report.passed, report.failed


def test_the_strap_pieces_stay_out_of_the_bore():
    """MuJoCo collides each piece's convex hull: none may reach into the bore, where the pins
    pass through the sheave."""
    points = np.array([(0.0, 0.0), (10.0, 0.0), (7.0, 7.0), (9.0, 3.0)])
    whole, pieces = strap_meshes(points, 3.0, 1.0, 0.4, 0.4)
    assert trimesh.Trimesh(whole.vertices, whole.faces).is_watertight
    for piece in pieces:
        hull = trimesh.Trimesh(piece.vertices, piece.faces).convex_hull
        assert np.linalg.norm(hull.vertices[:, :2], axis=1).min() >= 3.0 * (1 - 1e-6)


def test_astrap_moved_onto_the_pin_it_passes_is_caught(strapped, tmp_path):
    """The strap's pieces shifted towards pivot 7 by the bore's margin over it: the ring now
    crosses pin 7, which verification must name."""
    out, result, _ = strapped
    detail = strap_moved_onto(STRAPPED, out, result, tmp_path, "link_3_4", 3, 7)
    assert "pin_7" in detail and "link_3_4_piece" in detail


# Generated (seed 99, 7 to 13 joints, no. 198 of 300), in mm: no one strap or two lets it
# layer; three do, each found round the fewest whose crossings freed would layer.
THREE_STRAPS = Mechanism(
    [(-28.466, 81.827), (-12.825, 87.814), (-17.722, 56.812), (-47.458, 6.209),
     (-50.646, -28.55), (51.02, -45.211), (-74.375, -17.784), (-25.649, 47.206),
     (94.58, -1.132), (-86.3, 70.939), (-14.325, 26.385), (-41.417, 27.98),
     (-89.218, -82.202)],
    [1, 0, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0],
    [(0, 1), (0, 2), (0, 3), (1, 2), (1, 6), (1, 11), (2, 3), (2, 11), (3, 5), (3, 8), (4, 5),
     (4, 10), (5, 6), (5, 9), (5, 10), (5, 12), (7, 8), (8, 9), (11, 12)],
    (0, 1), 12, units="mm",
)  # fmt: skip


@pytest.fixture(scope="module")
def three(tmp_path_factory):
    out = tmp_path_factory.mktemp("three_straps")
    result, report = export_verified(THREE_STRAPS, out, {"mjcf", "stl"})
    return out, result, report


def test_three_straps_build_what_one_or_two_do_not(three):
    out, result, report = three
    assert report.passed, report.failed
    parts = {p["name"]: p for p in result.parts}
    sheaves = sorted(name for name, part in parts.items() if part["kind"] == "sheave")
    assert sheaves == ["link_11_12_sheave", "link_3_5_sheave", "link_7_8_sheave"]
    assert sheaves_crossed(THREE_STRAPS, out, parts, sheaves) >= 3  # pins cross their layers


def test_one_of_three_straps_moved_onto_its_pin_is_caught(three, tmp_path):
    """Link 7-8's strap, round a ground sheave at 7, shifted onto ground pin 4 that it passes."""
    out, result, _ = three
    detail = strap_moved_onto(THREE_STRAPS, out, result, tmp_path, "link_7_8", 7, 4)
    assert "pin_4" in detail and "link_7_8_piece" in detail


def sheaves_crossed(mech: Mechanism, out, parts: dict, sheaves) -> int:
    """How many pins cross a strap's layer through its sheave, once each sheave is checked: on
    its strap's layer and as wide as its bore, the pins it holds clear of the strap, the strap
    and sheave watertight."""
    crossed = 0
    for name in sheaves:
        sheave, strap = parts[name], parts[name.removesuffix("_sheave")]
        assert sheave["layer"] == strap["layer"] and sheave["diameter"] == strap["bore"]
        centre = mech.positions[sheave["joints"][0]]
        for joint in sheave["joints"][1:]:  # the pins it holds, clear of the strap
            pin = parts[f"pin_{joint}"]
            gap = strap["bore"] / 2 - np.linalg.norm(mech.positions[joint] - centre)
            assert gap >= pin["diameter"] / 2
            crossed += pin["layers"][0] <= strap["layer"] <= pin["layers"][1]
        for path in [strap["mesh"], sheave["mesh"], *strap["pieces"]]:
            assert trimesh.load(out / path).is_watertight
    return crossed


def strap_moved_onto(mech, out, result, tmp_path, strap: str, centre: int, joint: int) -> str:
    """Verification's collisions once the strap's pieces are shifted from the sheave's centre
    towards `joint` by the bore's margin over that pin and a pin's width more."""
    tree, geoms = editable_copy(out, tmp_path)
    parts = {p["name"]: p for p in result.parts}
    toward = mech.positions[joint] - mech.positions[centre]
    margin = parts[strap]["bore"] / 2 - np.linalg.norm(toward)
    shift = toward / np.linalg.norm(toward) * (margin + parts[f"pin_{joint}"]["diameter"])
    shift = shift * UNITS_IN_METRES[mech.units]
    for name, geom in geoms.items():
        if name and name.startswith(f"{strap}_piece"):
            x, y, z = map(float, geom.get("pos").split())
            geom.set("pos", f"{x + shift[0]} {y + shift[1]} {z}")
    return collision_detail(tree, tmp_path)
