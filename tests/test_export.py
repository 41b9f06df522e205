"""Export without simulation: parts, layers, meshes, files (linkd.export)."""

import json

import numpy as np
import pytest
import trimesh

from linkd import classic
from linkd.export import ExportOptions, export_mechanism, hinge_angles
from linkd.export.layers import (
    assign_layers,
    find_conflicts,
    hull_edges,
    stack_layers,
    sweep,
)
from linkd.export.meshes import SEGMENTS
from linkd.export.options import resolve_sizes
from linkd.export.parts import CRANK, assemble, rigid_parts
from linkd.export.planar import (
    convex_hull,
    least_distances,
    point_segment,
    segment_distance,
    to_segment,
)
from linkd.export.plates import plates
from linkd.export.rods import pin_rods
from linkd.geometry import Similarity, rotation
from linkd.mechanism import UNITS_IN_METRES, Mechanism

CLASSICS = [classic.crank_rocker, classic.jansen_leg, classic.watt_six_bar,
            classic.stephenson_six_bar]  # fmt: skip

# A generated mechanism whose ternary crank sweeps over the other ground pivot: the pins of the
# two ground joints cannot both stand in the base plate, one must hang from a cover plate.
CRANK_PLATE = Mechanism(
    [(29.054, 3.317), (9.352, 0.151), (30.119, -35.315), (38.261, 7.190), (6.904, -30.185),
     (25.920, 14.455)],
    [1, 0, 1, 0, 0, 0], [(0, 1), (0, 4), (1, 3), (1, 4), (1, 5), (2, 3), (3, 5)], (0, 1), 5,
)  # fmt: skip


# Generated (seed 2026, no. 58 of 200): refused before ground pins could be held from both
# plates. The crank and another link turn about ground joint 0 on either side of parts that
# pass over it: the crank on a pin standing in the base, the link on a stub from the cover.
SPLIT_GROUND = Mechanism(
    [(-61.366, -20.081), (-97.844, 6.461), (56.736, -27.458), (12.241, 80.915), (-9.267, -54.538),
     (-10.649, 24.046), (-49.631, 89.019), (-72.872, -8.282), (-43.573, 17.223), (-47.268, 28.713),
     (67.227, 84.743), (47.272, -62.57), (-71.128, -93.505), (81.673, 1.285), (38.959, 15.456),
     (38.409, 64.656), (53.482, -54.914), (-25.009, 96.707), (34.203, 27.156), (33.14, -72.062)],
    [1, 0, 1, 0, 1, 0, 0, 0, 0, 0, 1, 0, 1, 0, 0, 0, 0, 0, 0, 0],
    [(0, 1), (0, 6), (1, 3), (1, 5), (1, 9), (2, 3), (2, 7), (2, 8), (2, 9), (3, 13), (4, 5),
     (4, 17), (5, 6), (5, 19), (6, 7), (6, 18), (7, 8), (7, 14), (7, 19), (8, 18), (9, 11),
     (9, 15), (10, 11), (12, 13), (12, 14), (13, 15), (13, 16), (14, 16), (16, 17)],
    (0, 1), 19,
)  # fmt: skip


def _kinds(mech):
    return sorted((p.kind, p.joints) for p in rigid_parts(mech))


def test_rigid_parts_of_classics():
    assert _kinds(classic.crank_rocker()) == [
        ("ground", (0, 2)), ("link", (0, 1)), ("link", (2, 3)), ("plate", (1, 3, 4))
    ]  # fmt: skip
    jansen = _kinds(classic.jansen_leg())
    assert [j for k, j in jansen if k == "plate"] == [(2, 3, 5), (4, 6, 7)]
    assert sum(k == "link" for k, _ in jansen) == 5
    assert ("plate", (2, 3, 4)) in _kinds(classic.watt_six_bar())  # ternary rocker
    assert ("plate", (1, 3, 4)) in _kinds(classic.stephenson_six_bar())  # ternary coupler


def test_joint_hung_on_two_ground_joints_is_part_of_the_ground():
    mech = classic.crank_rocker()
    braced = mech.replace(
        positions=np.vstack([mech.positions, [2.0, -1.0]]),
        fixed=np.append(mech.fixed, False),
        links=[*mech.links, (0, 5), (2, 5)],
    )
    assert rigid_parts(braced)[0].joints == (0, 2, 5)


@pytest.mark.parametrize("build", [*CLASSICS, lambda: CRANK_PLATE])
def test_hinge_tree_leaves_one_freedom(build):
    mech = build()
    assembly = assemble(mech)
    assert len(assembly.hinges) == len(assembly.parts) - 1
    assert len(assembly.hinges) - 2 * len(assembly.loops) == 1
    crank = next(h for h in assembly.hinges if h.name == CRANK)
    assert crank.parent == 0 and crank.joint == mech.motor[0]
    assert set(assembly.parts[crank.child].joints) >= set(mech.motor)
    for loop in assembly.loops:
        pin = next(p for p in assembly.pins if p.joint == loop.joint)
        assert loop.hub == pin.hub and loop.part in pin.members


def test_hinge_angles_start_at_the_assembly_pose_and_follow_the_crank():
    mech = classic.jansen_leg()
    angles = np.linspace(0, 2 * np.pi, 7)
    result = hinge_angles(mech, angles)
    assert np.array_equal(result[CRANK], angles)
    for values in result.values():
        assert abs(values[0]) < 1e-12
        assert np.allclose(np.angle(np.exp(1j * values[-1])), 0, atol=1e-9)


def test_segment_distance_matches_dense_sampling():
    rng = np.random.default_rng(0)
    a1, a2, b1, b2 = rng.normal(size=(4, 100)) + 1j * rng.normal(size=(4, 100))
    t = np.linspace(0, 1, 121)[:, None]
    pa, pb = a1 + t * (a2 - a1), b1 + t * (b2 - b1)  # (121, 100) complex points
    dense = np.abs(pa[:, None] - pb[None]).min((0, 1))
    exact = segment_distance(a1, a2, b1, b2)
    assert np.all(exact <= dense + 1e-12)
    step = np.abs(np.concatenate([a2 - a1, b2 - b1])).max() / 120
    assert np.all(dense - exact <= step)
    assert np.all(segment_distance(a1, a2, a1, a2) == 0)


def _closed_paths(rng, count: int, angles: int) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, angles, endpoint=False)
    centre, cos, sin = rng.normal(size=(3, count, 1)) + 1j * rng.normal(size=(3, count, 1))
    return centre + cos * np.cos(t) + sin * np.sin(t)


@pytest.mark.parametrize("stride", [1, 7, 16, 33])
def test_least_distances_are_the_least_over_every_angle(stride):
    """Reckoned at a few angles and then only where segments may come nearer, the least
    distances are those over every angle, to the last bit; pairs said to move as one body
    (segments fixed in one turning frame) to rounding; asked only which are below a figure,
    the same ones are."""
    rng = np.random.default_rng(stride)
    t = np.linspace(0, 2 * np.pi, 1000, endpoint=False)
    origin, turn = _closed_paths(rng, 1, 1000)[0], np.exp(1j * (t + 0.3 * np.sin(3 * t)))
    a1, a2, r1, r2 = (origin + turn * (rng.normal(size=(3, 1)) + 1j * rng.normal(size=(3, 1)))
                      for _ in range(4))  # fmt: skip
    b1, b2 = (np.concatenate([_closed_paths(rng, 4, 1000), r]) for r in (r1, r2))
    every = segment_distance(a1[:, None], a2[:, None], b1, b2).min(-1)
    assert np.array_equal(least_distances(a1, a2, b1, b2, stride=stride), every)
    rigid = np.zeros(every.shape, bool)
    rigid[:, 4:] = True  # the riders in a's frame
    assert np.allclose(least_distances(a1, a2, b1, b2, rigid=rigid, stride=stride), every,
                       rtol=1e-12, atol=0)  # fmt: skip
    both = segment_distance(b1[:, None], b2[:, None], b1, b2).min(-1)
    assert np.array_equal(least_distances(b1, b2, b1, b2, symmetric=True, stride=stride), both)
    to_point = least_distances(a1, a1, b1, b2, to_segment)
    assert np.array_equal(to_point, point_segment(a1[:, None], b1, b2).min(-1))
    for below in np.quantile(every, [0.1, 0.5, 0.9]):  # only which are nearer, reckoned less
        nearer = least_distances(a1, a2, b1, b2, stride=stride, below=below) < below
        assert np.array_equal(nearer, every < below)


def test_conflicts_are_those_reckoned_at_every_angle(monkeypatch):
    """A Jansen leg's plates and ground keep their joints' distances: those pairs are reckoned
    at a few angles, the rest where they may come near; the conflicts are the same as where
    every pair is reckoned at every angle."""
    from linkd.export import layers

    mech = classic.jansen_leg()
    assembly = assemble(mech)
    sizes = resolve_sizes(mech, assembly.parts, None)
    paths = sweep(mech, sizes.link_width)
    fast = find_conflicts(assembly, paths, sizes)

    def at_every_angle(a1, a2, b1, b2, distance=segment_distance, **_):
        return distance(a1[:, None], a2[:, None], b1, b2).min(-1)

    monkeypatch.setattr(layers, "least_distances", at_every_angle)
    slow = find_conflicts(assembly, paths, sizes)
    assert np.array_equal(fast.parts, slow.parts) and fast.blocked == slow.blocked
    assert np.allclose(fast.distance, slow.distance, rtol=1e-12, atol=1e-9)


def test_pairs_that_keep_their_distance_are_those_reckoned_pair_by_pair():
    """The joints of a Jansen leg with still points beside them (as a bracket's posts are):
    the pairs found to keep their distance are those whose distance over every angle says so,
    the still points among them all, and the joints of one plate."""
    from linkd.export.layers import _fixed_apart

    mech = classic.jansen_leg()
    paths = sweep(mech, resolve_sizes(mech, assemble(mech).parts, None).link_width)
    points = paths[..., 0] + 1j * paths[..., 1]
    still = np.repeat(np.array([3 + 4j, -20 + 1j, 7 - 9j])[:, None], points.shape[1], 1)
    points = np.concatenate([points, still])
    gaps = np.abs(points[:, None] - points[None]) ** 2
    keep = np.ptp(gaps, -1) <= 1e-9 * np.abs(points).max() ** 2
    fixed = _fixed_apart(points)
    assert np.array_equal(fixed, keep)
    assert fixed[-3:, -3:].all() and fixed[-3:, np.flatnonzero(mech.fixed)].all()
    assert 0 < fixed[: len(paths), : len(paths)].sum() - len(paths) < len(paths) ** 2 / 2


def test_convex_hull_is_counter_clockwise_and_drops_interior_points():
    points = np.array([[0, 0], [1, 0], [0.5, 0.5], [1, 1], [0, 1], [0.5, 0.0]])
    assert convex_hull(points) == [0, 1, 3, 4]
    assert sorted(convex_hull(np.array([[0, 0], [2, 0], [1, 0]]))) == [0, 1]


def _swept_layout(mech, stubs: bool = False, fewest: bool = True):
    """Layers as `assign_layers` finds them (stubs: with ground stubs allowed, as `braced`;
    fewest: as `stack_layers`)."""
    assembly = assemble(mech)
    sizes = resolve_sizes(mech, assembly.parts, None)
    paths = sweep(mech, sizes.link_width)
    conflicts = find_conflicts(assembly, paths, sizes)
    layout = stack_layers(assembly, conflicts, sizes, stubs=stubs, fewest=fewest)
    return assembly, sizes, paths, layout


def _dense_outline(assembly, part, paths, per_edge=20):
    """(K, T, 2) points along a part's joint hull, for a brute-force distance."""
    t = np.linspace(0, 1, per_edge)[:, None, None]
    edges = [(a, b) for p, a, b in hull_edges(assembly, paths[:, 0]) if p == part]
    return np.concatenate([paths[a] + t * (paths[b] - paths[a]) for a, b in edges])


@pytest.mark.parametrize(
    ("build", "stubs", "fewest"),
    [(classic.jansen_leg, False, True), (classic.watt_six_bar, False, True),
     (lambda: CRANK_PLATE, False, True), (lambda: SPLIT_GROUND, True, True),
     (classic.jansen_leg, False, False), (lambda: SPLIT_GROUND, True, False)],
)  # fmt: skip
def test_parts_of_one_layer_stay_apart_and_pins_clear(build, stubs, fewest):
    """Brute force over the sweep: plates sharing a layer keep a width plus the clearance
    between their joint hulls; no pin (or stub of one) crosses a layer where a part it does not
    join passes. So too for the first layering found, without the search for the fewest (as
    the costlier constructions' bounds ask), which never has fewer layers."""
    mech = build()
    assembly, sizes, paths, layout = _swept_layout(mech, stubs, fewest)
    if not fewest:
        assert not layout.minimal
        assert layout.count >= _swept_layout(mech, stubs)[3].count
    n = len(assembly.parts)
    outline = [_dense_outline(assembly, p, paths) for p in range(n)]
    for p in range(1, n):
        for q in range(p + 1, n):
            if layout.layers[p] == layout.layers[q]:
                gap = np.linalg.norm(outline[p][:, None] - outline[q][None], axis=-1).min()
                assert gap >= sizes.link_width + sizes.clearance
    for rod in pin_rods(assembly, layout):
        lo, hi = rod.span
        for q in range(1, n):
            if q not in rod.members and lo <= layout.layers[q] <= hi:
                gap = np.linalg.norm(outline[q] - paths[rod.joint], axis=-1).min()
                assert gap >= (sizes.link_width + sizes.hole_diameter) / 2 + sizes.clearance


def test_ground_pins_stand_in_the_base_or_hang_from_the_cover():
    assembly, _, _, layout = _swept_layout(CRANK_PLATE)
    assert layout.top_joints  # this one needs the cover
    names = {p.name: p.layer for p in plates(assembly, layout)}
    assert names["ground"] == 0 and names["ground_cover"] == layout.count - 1
    for pin, (lo, hi) in zip(assembly.pins, layout.pin_spans):
        if 0 in pin.members:
            assert lo == 0 or hi == layout.count - 1
    jansen = _swept_layout(classic.jansen_leg())[3]
    assert jansen.top_joints == () and jansen.minimal


def test_a_pin_of_the_ground_names_the_ground_plate_it_stands_in(tmp_path):
    parts = {p["name"]: p for p in export_mechanism(CRANK_PLATE, tmp_path, set()).parts}
    pins = [p for p in parts.values() if p["kind"] == "pin" and "ground" in " ".join(p["joins"])]
    assert {name for pin in pins for name in pin["joins"]} >= {"ground", "ground_cover"}
    for pin in pins:
        (plate,) = [parts[name] for name in pin["joins"] if name.startswith("ground")]
        assert pin["joints"][0] in plate["joints"] and plate["layer"] in pin["layers"]


def test_a_ground_pin_held_from_both_plates_is_two_stubs_either_side_of_the_passing_parts():
    """Where neither base nor cover can hold a ground pin whole, its parts below the parts that
    pass over the joint turn on a pin standing in the base, those above on a stub hanging from
    the cover; the two stubs leave the passing parts' layers free."""
    assembly, sizes, paths, layout = _swept_layout(SPLIT_GROUND, stubs=True)
    with pytest.raises(ValueError, match="flat layers"):  # whole ground pins
        assign_layers(assembly, paths, sizes)
    assert layout.cover_stubs and not layout.brackets and not layout.arms
    top = layout.count - 1
    for k, (lo, hi) in layout.cover_stubs.items():
        pin = assembly.pins[k]
        base = layout.pin_spans[k]
        assert 0 in pin.members and base[0] == 0 and hi == top
        rods = [r for r in pin_rods(assembly, layout) if r.joint == pin.joint]
        assert [r.name for r in rods] == [pin.name, f"{pin.name}_top"]
        below, above = ({m for m in r.members if m} for r in rods)
        assert below and above and below | above == set(pin.members) - {0}
        between = [q for q in range(1, len(assembly.parts)) if base[1] < layout.layers[q] < lo]
        assert between  # a pin whole from either plate would cross these
    cover = next(p for p in plates(assembly, layout) if p.name == "ground_cover")
    assert {assembly.pins[k].joint for k in layout.cover_stubs} <= set(cover.joints)


def test_reflected_rotated_mechanism_has_the_same_parts_and_layers():
    mech = classic.jansen_leg()
    moved = mech.transformed(Similarity(3.0, rotation(0.7, reflect=True), np.array([5.0, -2.0])))
    a, b = _swept_layout(mech), _swept_layout(moved)
    assert a[0].parts == b[0].parts
    assert a[3].count == b[3].count


def test_export_writes_the_contract_files(tmp_path):
    mech = classic.jansen_leg()
    result = export_mechanism(mech, tmp_path)
    names = {str(f) for f in result.files}
    assert {"mechanism.json", "mechanism.xml", "scene.xml"} <= names
    assert all((tmp_path / f).is_file() for f in result.files)
    saved = json.loads((tmp_path / "mechanism.json").read_text())
    assert saved["layers"] == result.layers >= 2
    assert saved["parts"] == result.parts
    again = Mechanism.load(tmp_path / "mechanism.json")
    assert np.array_equal(again.positions, mech.positions) and again.links == mech.links
    pins = [p for p in result.parts if p["kind"] == "pin"]
    assert len(pins) == 7 and all(p["layers"][0] < p["layers"][1] for p in pins)
    meshes = {p["mesh"] for p in result.parts if "mesh" in p}
    assert meshes == {n for n in names if n.endswith(".stl")} and len(meshes) == 8


def test_stl_plates_are_watertight_with_the_expected_volume(tmp_path):
    mech = classic.crank_rocker().transformed(Similarity(25.0))
    result = export_mechanism(mech, tmp_path, {"stl"})
    sizes = result.sizes
    unit = UNITS_IN_METRES[mech.units]
    w, d, t = (sizes[k] * unit for k in ("link_width", "hole_diameter", "thickness"))
    polygon = SEGMENTS / (2 * np.pi) * np.sin(2 * np.pi / SEGMENTS)  # inscribed circle area
    for part in result.parts:
        if "mesh" not in part:
            continue
        mesh = trimesh.load(tmp_path / part["mesh"])
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        if part["kind"] == "link":
            length = np.linalg.norm(np.subtract(*mech.positions[part["joints"]])) * unit
            area = length * w + polygon * np.pi * (w**2 - 2 * d**2) / 4
            assert mesh.volume == pytest.approx(area * t, rel=5e-3)
    assert not (tmp_path / "mechanism.xml").exists()


def test_mjcf_alone_uses_boxes_and_cylinders(tmp_path):
    import mujoco

    export_mechanism(classic.crank_rocker().transformed(Similarity(25.0)), tmp_path, {"mjcf"})
    assert not (tmp_path / "meshes").exists()
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "mechanism.xml"))
    kinds = {mujoco.mjtGeom(k).name for k in model.geom_type}
    assert kinds == {"mjGEOM_BOX", "mjGEOM_CYLINDER"}


def test_mjcf_alone_with_a_ground_frame_at_one_pivot(tmp_path):
    """The motor pivot sits on a crank plate, so the ground part holds one joint: a boss."""
    import mujoco

    from linkd.verify import verify_output

    mech = Mechanism(
        [(-8.51, 5.92), (-0.94, -15.22), (-67.75, -40.7), (-13.99, 13.36), (12.08, -5.04),
         (-9.28, 8.03), (-18.43, -5.92), (6.29, -30.06)],
        [1, 0, 0, 0, 1, 0, 0, 0],
        [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 5), (2, 6), (3, 6), (4, 5), (5, 7), (6, 7)],
        (0, 1), 7,
    )  # fmt: skip
    export_mechanism(mech, tmp_path, {"mjcf"})
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "mechanism.xml"))
    assert model.ngeom > 0
    assert verify_output(tmp_path, write=False).passed


def test_invalid_input_is_refused(tmp_path):
    with pytest.raises(ValueError, match="locks"):
        export_mechanism(classic.non_grashof_four_bar(), tmp_path)
    with pytest.raises(ValueError, match="format"):
        export_mechanism(classic.crank_rocker(), tmp_path, {"step"})
    with pytest.raises(ValueError, match="hole"):
        export_mechanism(classic.crank_rocker(), tmp_path, options=ExportOptions(hole_diameter=9))
    assert not any(tmp_path.iterdir())
