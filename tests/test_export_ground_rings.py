"""Parts at other ground pivots on rings (linkd.export.ground_rings): where no pin, stub or
bracket can hold a ground pivot, the parts turning about it are rings in ground rings of their
own, each ground ring held by a lug on a post. The last construction tried, so a mechanism it
builds was refused by every other; built and verified in MuJoCo, no pin crosses a lug's bar,
and a ring planted off its bearing's centre is caught."""

import json

import mujoco
import numpy as np
import pytest
import trimesh
from planted import collision_detail, editable_copy

from linkd.export.parts import joint_paths
from linkd.export.planar import point_segment
from linkd.mechanism import Mechanism
from linkd.verified import export_verified

# Generated (seed 17, no. 29 of 200, 5 to 20 joints), in mm. At ground pivots 7 and 15 the
# parts turning about them sweep over pins on both sides of them in every order: no pin, stub
# or bracket there keeps clear, and the crank's shaft must be cut in two as well.
RINGED = Mechanism(
    [(25.823, 68.411), (64.187, 36.523), (-48.418, -8.064), (74.397, -79.182), (-71.67, 56.801),
     (-91.45, -89.547), (-48.148, 63.999), (52.902, -92.931), (-9.475, 90.673), (-92.606, 71.62),
     (-64.093, -76.565), (77.235, -73.977), (-17.112, -27.689), (60.254, -3.912),
     (-60.296, -26.587), (40.335, -58.407), (-12.161, -9.708), (85.015, -50.288),
     (-96.652, -93.291)],
    [1, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 1, 0, 1, 0, 0, 0],
    [(0, 1), (0, 5), (0, 11), (1, 3), (1, 4), (1, 5), (1, 6), (1, 10), (1, 11), (2, 3), (2, 9),
     (3, 4), (3, 9), (3, 14), (4, 12), (5, 6), (5, 8), (7, 8), (7, 10), (8, 18), (10, 12),
     (10, 16), (12, 17), (13, 14), (15, 16), (16, 17), (17, 18)],
    (0, 1), 18, units="mm",
)  # fmt: skip
PIVOTS = {"link_7_8": 7, "link_7_10": 7, "link_15_16": 15}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("ground_rings")
    result, report = export_verified(RINGED, out, {"mjcf", "stl"})
    parts = {p["name"]: p for p in json.loads((out / "mechanism.json").read_text())["parts"]}
    return out, result, report, parts


def _bearings(parts: dict) -> dict[str, dict]:
    """Each ring part's ground ring: the ground plate round its pivot on its layer."""
    return {name: next(p for p in parts.values() if p["kind"] == "ground" and "bore" in p
                       and p["joints"] == [PIVOTS[name]] and p["layer"] == parts[name]["layer"])
            for name in PIVOTS}  # fmt: skip


def test_the_parts_at_two_ground_pivots_turn_in_rings_held_by_lugs(built):
    out, result, report, parts = built
    assert report.passed, report.failed
    assert set(result.lugged) == set(PIVOTS) and not result.turntables
    assert result.drive == "drive_layshaft"  # the crank's shaft cut as well
    pins = [p for p in parts.values() if p["kind"] == "pin"]
    assert not any(set(p["joins"]) & set(PIVOTS) for p in pins if p["joints"][0] in (7, 15))
    posts = {tuple(p["at"]): p["layers"] for p in parts.values() if p["kind"] == "post"}
    top = json.loads((out / "mechanism.json").read_text())["layers"] - 1
    for name, bearing in _bearings(parts).items():
        ring = parts[name]
        assert bearing["bore"] == pytest.approx(ring["disc"] + 2 * result.sizes["clearance"])
        (lug,) = map(tuple, bearing["posts"])  # one lug, on a post from the base or the cover
        low, high = posts[lug]
        assert low <= ring["layer"] <= high and (low == 0 or high == top)
        for part in (ring, bearing):
            assert trimesh.load(out / part["mesh"]).is_watertight
    model = mujoco.MjModel.from_xml_path(str(out / "mechanism.xml"))
    for name, pivot in PIVOTS.items():  # each ring hinged at its pivot, with no pin there
        body = model.body(name)
        assert model.joint(f"hinge_{name}").type == mujoco.mjtJoint.mjJNT_HINGE
        assert body.pos[:2] * 1000 == pytest.approx(RINGED.positions[pivot] - RINGED.positions[0])


def test_no_pin_crosses_a_lugs_bar_or_a_ground_ring(built):
    """Over a revolution, every pin through a ring's layer (not the ring part's own) keeps a
    bar's half width and its own radius from the bar out to the lug, and stays off the ring
    part and its ground ring (inside the part's hole or outside the ground ring)."""
    _, result, _, parts = built
    width, pin = result.sizes["link_width"], result.sizes["hole_diameter"] / 2
    paths = joint_paths(RINGED, np.linspace(0, 2 * np.pi, 720, endpoint=False))
    points = paths[..., 0] + 1j * paths[..., 1]
    crossing = 0
    for name, bearing in _bearings(parts).items():
        layer, centre = parts[name]["layer"], complex(*RINGED.positions[PIVOTS[name]])
        lug = np.complex128(complex(*bearing["posts"][0]))
        hole, rim = parts[name].get("bore", 0) / 2, bearing["bore"] / 2 + width / 2
        start = centre + rim * (lug - centre) / abs(lug - centre)
        for p in parts.values():
            if p["kind"] != "pin" or name in p["joins"] or p["joints"][0] >= len(points):
                continue
            if not p["layers"][0] <= layer <= p["layers"][1]:
                continue
            crossing += 1
            path = points[p["joints"][0]]
            assert point_segment(path, start, lug).min() > width / 2 + pin
            away = np.abs(path - centre)
            assert (away + pin < hole).all() or (away - pin > rim).all()
    assert crossing  # pins do cross the rings' layers


def test_a_ring_planted_off_its_bearings_centre_is_caught(built, tmp_path):
    out, result, _, _ = built
    tree, geoms = editable_copy(out, tmp_path)
    shift = 2 * result.sizes["clearance"] / 1000  # metres: more than the gap all round
    for name, geom in geoms.items():
        if name and name.startswith("link_15_16"):
            x, y, z = map(float, geom.get("pos").split())
            geom.set("pos", f"{x + shift} {y} {z}")
    detail = collision_detail(tree, tmp_path)
    assert "link_15_16" in detail and "ground_ring" in detail
