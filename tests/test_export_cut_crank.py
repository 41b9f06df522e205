"""A crank cut in two at the motor's shaft (linkd.export.braced.cut_crank_layers,
linkd.export.drive): its halves on stubs from base and cover, turned as one by a layshaft and
eccentric rods outside the stack. Refused before; built and verified in MuJoCo; the drive is
what holds the halves together, and a rod planted on its neighbour's layer is caught."""

import json

import mujoco
import numpy as np
import pytest
import trimesh
from planted import collision_detail, editable_copy

from linkd.export import braced
from linkd.export.braced import cut_crank_layers, split_straps_layers
from linkd.export.layers import NoFlatLayers, sweep
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.mechanism import Mechanism
from linkd.verified import export_verified
from linkd.verify.pose import Connects, loop_closure

# Generated (seed 2026, no. 282 of 300, 7 to 13 joints), in mm. Parts passing over the motor's
# pivot must lie between the arms of the crank (plate 0-1-4): no whole shaft there keeps clear.
CUT = Mechanism(
    [(-66.932, -18.721), (-30.258, -35.431), (1.3, 7.1), (-93.286, 95.915), (-9.792, 64.781),
     (-71.123, 77.376), (2.404, -32.151), (-38.978, 6.831), (26.526, -99.481), (-67.31, -30.859),
     (-42.631, -77.053), (91.015, 58.934), (-91.242, -26.834)],
    [1, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0],
    [(0, 1), (0, 4), (1, 3), (1, 4), (1, 5), (1, 6), (2, 3), (2, 5), (3, 6), (3, 10), (4, 8),
     (4, 12), (5, 9), (6, 9), (6, 10), (7, 8), (8, 11), (9, 11), (11, 12)],
    (0, 1), 12, units="mm",
)  # fmt: skip
# Generated (seed 17, no. 149 of 200, 5 to 20 joints), in mm. Refused while the cut crank's
# search spent its splits on plates other than the crank (the first 16 left it whole, as
# split plates with straps had already tried): only a split of the crank at the motor is new.
AT_THE_MOTOR = Mechanism(
    [(95.569, 44.595), (85.718, 77.033), (-28.23, -88.005), (34.378, -26.584), (-66.074, 44.995),
     (-85.515, 21.946), (23.676, 59.175), (-65.004, 93.334), (-3.489, 13.27), (34.621, -17.109),
     (-80.137, 16.437), (-4.333, 36.397), (3.502, -12.02)],
    [1, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 4), (2, 7), (2, 8), (3, 4), (3, 5), (4, 5), (4, 11), (5, 9),
     (5, 11), (5, 12), (6, 7), (6, 9), (6, 10), (7, 8), (7, 10), (7, 12)],
    (0, 1), 12, units="mm",
)  # fmt: skip
# Generated (seed 12, no. 88 of 200, 5 to 20 joints), in mm. Refused while the cut crank's
# search tried straps on its first splits alone: the 26th split of the crank at the motor layers
# with no strap at all, which is now asked first, exactly, of many splits.
STRAPLESS = Mechanism(
    [(-57.341, 17.705), (-33.283, -17.689), (44.393, 87.591), (-26.33, -28.34), (-41.925, 94.309),
     (-20.629, -52.147), (70.58, -35.747), (59.437, -66.911), (35.01, 96.65), (-41.527, -59.855),
     (-86.573, 74.549), (54.996, 75.077), (67.568, 10.632), (-61.301, -69.733), (67.056, -87.22),
     (42.958, 15.937), (68.826, 47.205), (84.158, -60.987), (14.317, -79.474)],
    [1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 3), (1, 12), (1, 18), (2, 3), (2, 5), (2, 9), (2, 15), (3, 8),
     (4, 5), (4, 6), (4, 7), (5, 6), (5, 10), (5, 14), (6, 7), (6, 8), (6, 9), (6, 10), (6, 14),
     (9, 15), (10, 13), (10, 17), (11, 12), (11, 13), (11, 16), (13, 16), (13, 17), (16, 18)],
    (0, 1), 18, units="mm",
)  # fmt: skip
CRANK, UPPER = "plate_0_1_4", "plate_0_1_4_upper"
RODS = [f"drive_rod{k}" for k in range(4)]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("cut_crank")
    result, report = export_verified(CUT, out, {"mjcf", "stl"})
    return out, result, report


def test_no_whole_motor_shaft_builds_it():
    assembly = assemble(CUT)
    sizes = resolve_sizes(CUT, assembly.parts, None)
    with pytest.raises(NoFlatLayers):
        split_straps_layers(assembly, sweep(CUT, sizes.link_width), sizes)


def test_the_cut_crank_is_built_and_verified(built):
    out, result, report = built
    assert report.passed, report.failed
    assert result.drive == "drive_layshaft"
    saved = json.loads((out / "mechanism.json").read_text())
    parts = {p["name"]: p for p in saved["parts"]}
    base, cover = parts["pin_0"], parts["pin_0_top"]  # the motor's shaft, cut into two stubs
    assert base["fixed_in"] == CRANK and cover["fixed_in"] == UPPER
    assert base["layers"][1] < cover["layers"][0]  # parts pass over the pivot between them
    halves = {n: [p for p in parts.values() if p.get("arm_of") == n] for n in (CRANK, UPPER)}
    assert all(halves.values())
    assert max(p["layer"] for p in halves[CRANK]) <= base["layers"][1]
    assert min(p["layer"] for p in halves[UPPER]) >= cover["layers"][0]
    first = saved["drive"]["first_joint"]
    assert first == CUT.n_nodes and len(saved["drive"]["points"]) == 13
    layshaft = parts["drive_layshaft_shaft"]
    assert layshaft["joints"] == [first] and layshaft["fixed_in"] == "drive_layshaft"
    assert first in parts["ground"]["joints"] and first in parts["ground_cover"]["joints"]
    rods = [p for p in parts.values() if p.get("arm_of") in RODS]
    assert {p["layer"] for p in rods} == {-2, -1, saved["layers"], saved["layers"] + 1}
    assert all("bore" in p for p in rods)  # strapped round eccentrics at both ends
    for p in rods + halves[UPPER]:
        assert trimesh.load(out / p["mesh"]).is_watertight
    model = mujoco.MjModel.from_xml_path(str(out / "mechanism.xml"))
    for hinge in ("crank", f"hinge_{UPPER}", "hinge_drive_layshaft"):
        assert model.joint(hinge).type == mujoco.mjtJoint.mjJNT_HINGE


def test_the_drive_alone_holds_the_halves_together(built):
    """One freedom with the rods over the cover; without them the upper half turns freely."""
    out, _, _ = built
    model = mujoco.MjModel.from_xml_path(str(out / "mechanism.xml"))
    data = mujoco.MjData(model)

    def freedoms() -> int:
        _, jacobian = loop_closure(model, data, model.qpos0.copy(), Connects.of(model, data))
        values = np.linalg.svd(jacobian, compute_uv=False)
        return model.nv - int((values > 1e-9 * values[0]).sum())

    assert freedoms() == 1
    for k in (2, 3):
        data.eq_active[model.equality(f"loop_drive_rod{k}").id] = 0
    assert freedoms() == 4  # the crank, the upper half, and each loose rod on its hinge


def test_the_drive_closes_its_loops_as_stiffly_as_the_mechanism(built):
    """MuJoCo softens each loop closure by its estimate of the anchors' inverse weights: no
    closure, the drive's included, is softer than the exact effective mass makes it by more than
    twice (anchored on the layshaft's massless hub, the drive's were 5 to 7 times, and a heavy
    strapped crank then drifted out of step with its upper half: seed 19's no. 162)."""
    out, _, _ = built
    model = mujoco.MjModel.from_xml_path(str(out / "mechanism.xml"))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    rows = np.flatnonzero(data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY)
    jacobian = data.efc_J.reshape(data.nefc, model.nv)[rows]
    solved = np.zeros_like(jacobian)
    mujoco.mj_solveM(model, data, solved, jacobian)
    exact = np.einsum("ij,ij->i", jacobian, solved)  # the rows' inverse effective masses
    impedance = model.eq_solimp[data.efc_id[rows], 0]
    planar = exact > 1e-9 * exact.max()  # the z rows of planar loops carry nothing
    softness = data.efc_R[rows] / ((1 - impedance) / impedance * exact)
    drive = [model.equality(i).name.startswith("loop_drive") for i in data.efc_id[rows]]
    assert np.any(planar & drive)
    assert softness[planar].max() <= 2.0


def test_a_rod_planted_on_its_neighbours_layer_is_caught(built, tmp_path):
    out, _, _ = built
    tree, geoms = editable_copy(out, tmp_path)
    pitch = None
    for name, geom in geoms.items():
        if name and name.startswith("drive_rod1_"):  # down one layer: onto rod 0's
            x, y, z = map(float, geom.get("pos").split())
            zero = float(geoms["drive_rod0_arm0_piece0"].get("pos").split()[2])
            pitch = pitch or (zero - z)
            geom.set("pos", f"{x} {y} {z + pitch}")
    detail = collision_detail(tree, tmp_path)
    assert "drive_rod1" in detail and "drive_rod0" in detail


def test_the_cut_crank_search_spends_its_splits_on_the_crank(tmp_path):
    assembly = assemble(AT_THE_MOTOR)
    sizes = resolve_sizes(AT_THE_MOTOR, assembly.parts, None)
    with pytest.raises(NoFlatLayers):
        split_straps_layers(assembly, sweep(AT_THE_MOTOR, sizes.link_width), sizes)
    result, report = export_verified(AT_THE_MOTOR, tmp_path, {"mjcf", "stl"})
    assert report.passed, report.failed
    assert result.drive == "drive_layshaft"
    saved = json.loads((tmp_path / "mechanism.json").read_text())
    stubs = {p["name"]: p["fixed_in"] for p in saved["parts"] if p["name"].startswith("pin_0")}
    assert stubs == {"pin_0": "plate_0_1_2", "pin_0_top": "plate_0_1_2_upper"}


def test_a_split_that_layers_with_no_strap_is_found_first(tmp_path, monkeypatch):
    assembly = assemble(STRAPLESS)
    sizes = resolve_sizes(STRAPLESS, assembly.parts, None)
    paths = sweep(STRAPLESS, sizes.link_width)
    with monkeypatch.context() as patch:
        patch.setattr(braced, "MAX_CUT_SCREENED", 0)  # the straps' search alone, as before
        with pytest.raises(NoFlatLayers):
            cut_crank_layers(assembly, paths, sizes)
    assert not cut_crank_layers(assembly, paths, sizes).straps
    result, report = export_verified(STRAPLESS, tmp_path, {"mjcf", "stl"})
    assert report.passed, report.failed
    assert result.drive == "drive_layshaft"
    saved = json.loads((tmp_path / "mechanism.json").read_text())
    sheaves = [p["name"] for p in saved["parts"] if p["kind"] == "sheave"]
    assert sheaves and all(name.startswith("drive_") for name in sheaves)  # the drive's alone
