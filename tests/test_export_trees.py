"""Plates cut into arms along their own links (linkd.export.braced): a crank plate that no star
of arms can layer is built as a crankshaft, verified in MuJoCo, and a planted collision of one
of its arms is caught."""

import pytest
import trimesh
from planted import collision_detail, editable_copy

import linkd.export.braced as braced
import linkd.export.forked_straps as forked_straps
from linkd.export import export_mechanism
from linkd.mechanism import Mechanism
from linkd.verified import export_verified

pytestmark = pytest.mark.usefixtures("straps_and_frames_off")  # built otherwise with those

# Generated (seed 2026, no. 147 of 200). Links 1-4, 2-7 and 6-8 hang on the crank plate
# 0-1-2-6 and each sweeps over the others' joints in the plate's frame; ground pivot 0 is
# swept too. Cut into arms from one shaft, the plate stays refused; cut along its own links
# 0-1, 1-2, 2-6 it is a crankshaft, each link turning on its crankpin between two arms.
CRANKSHAFT = Mechanism(
    [(8.293, -62.244), (16.234, -49.822), (39.239, -59.276), (24.038, -90.942), (-57.4, -67.639),
     (76.013, 90.466), (0.235, -99.744), (17.797, 86.89), (-95.541, 38.04)],
    [1, 0, 0, 1, 0, 0, 0, 0, 0],
    [(0, 1), (0, 2), (0, 5), (1, 2), (1, 4), (1, 6), (2, 6), (2, 7), (3, 4), (4, 5), (4, 7),
     (6, 8), (7, 8)],
    (0, 1), 8,
)  # fmt: skip


@pytest.fixture(scope="module")
def crankshaft(tmp_path_factory):
    out = tmp_path_factory.mktemp("crankshaft")
    result, report = export_verified(CRANKSHAFT, out, {"mjcf", "stl"})
    return out, result, report


def test_a_plate_no_star_layers_is_cut_along_its_own_links(monkeypatch, tmp_path):
    monkeypatch.setattr(braced, "_own_trees", lambda part, stars, points: [])
    monkeypatch.setattr(forked_straps, "MAX_CORES", 0)  # the last construction builds it too
    with pytest.raises(ValueError, match="flat layers"):
        export_mechanism(CRANKSHAFT, tmp_path, {"mjcf"})


def test_the_crankshaft_is_built_and_verified(crankshaft):
    out, result, report = crankshaft
    assert report.passed, report.failed
    parts = {p["name"]: p for p in result.parts}
    arms = {tuple(p["joints"]): p["layer"] for p in result.parts if "arm_of" in p}
    assert set(arms) == {(0, 1), (1, 2), (2, 6)}  # links of the plate, not a star
    for joint, (low, high), link in ((1, ((0, 1), (1, 2)), "link_1_4"),
                                     (2, ((1, 2), (2, 6)), "link_2_7")):  # fmt: skip
        pin = parts[f"pin_{joint}"]
        assert pin["fixed_in"] == "plate_0_1_2_6"  # the crankpin turns with the arms
        assert sorted([arms[low], arms[high]]) == pin["layers"]
        assert min(pin["layers"]) < parts[link]["layer"] < max(pin["layers"])
    for part in result.parts:
        if "mesh" in part:
            solid = trimesh.load(out / part["mesh"])
            assert solid.is_watertight and solid.is_volume


def test_an_arm_lowered_onto_its_crankpin_link_is_caught(crankshaft, tmp_path):
    """The middle arm (layer 4) laid on the layer of link 1-4 (layer 3), which turns on the
    same crankpin: their bosses overlap, and verification must name the arm."""
    out, result, _ = crankshaft
    tree, geoms = editable_copy(out, tmp_path)
    arm = next(p["name"] for p in result.parts if p.get("joints") == [1, 2] and "arm_of" in p)
    x, y, _ = geoms[arm].get("pos").split()
    z = geoms["link_1_4"].get("pos").split()[2]
    geoms[arm].set("pos", f"{x} {y} {z}")
    assert arm in collision_detail(tree, tmp_path)
