"""Several parts forked at once (linkd.export.forkset screens the sets, linkd.export.forked
builds them): mechanisms no single fork builds are built and verified in MuJoCo, with and
without a bracket, the screen's sets are minimal and share no joint, and a planted collision
of a cut rod is caught."""

from itertools import combinations

import numpy as np
import pytest
import trimesh
from planted import collision_detail, editable_copy
from pysat.solvers import Solver

import linkd.export.braced as braced
import linkd.export.forked as forked
import linkd.export.forked_rings as forked_rings
import linkd.export.ground_rings as ground_rings
import linkd.export.strapped as strapped
from linkd.export import export_mechanism
from linkd.export.braced import best_brackets, swept_candidates
from linkd.export.forkset import _Screen, fork_sets
from linkd.export.layers import sweep
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.mechanism import Mechanism
from linkd.verified import export_verified

# Generated (`generate(300, 7, GeneratorSettings(min_nodes=7, max_nodes=13))`, no. 237, scaled
# to 100 mm and rounded to the micrometre). Every straight, bent, strapped, split and single
# fork layering is refused; the crank plate forked at joint 3 together with link 4-5 forked at
# joint 5 layers, each cutting the pins of its other joints into rods.
TRIPOD = Mechanism(
    [(-17.937, -32.98), (-12.401, -65.647), (64.907, -24.394), (-73.523, -45.027),
     (-9.634, -35.511), (-42.03, -49.445), (40.591, 40.209), (-37.733, 63.699),
     (91.306, -40.119), (-90.161, -51.978), (-4.313, 1.452), (51.604, -71.319),
     (63.2, 57.322)],
    [1, 0, 0, 0, 1, 0, 1, 0, 0, 0, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 3), (1, 5), (1, 9), (1, 11), (2, 3), (3, 7), (3, 12), (4, 5),
     (4, 9), (4, 11), (5, 8), (6, 7), (6, 10), (7, 8), (8, 10), (8, 12)],
    (0, 1), 12,
)  # fmt: skip


# Generated (`generate(300, 2026, GeneratorSettings(min_nodes=7, max_nodes=13))`, no. 16,
# scaled and rounded the same way). The crank plate must be held from inside the stack, and
# no single fork layers: the crank forked at its pivot round a bracket, with plate 5-7-9
# forked at joint 5, does.
BRACED = Mechanism(
    [(1.159, -12.052), (22.473, -30.813), (-11.431, 91.667), (84.374, -72.085),
     (98.154, 34.753), (-50.299, -63.501), (14.433, -0.164), (48.019, -19.33),
     (-74.687, 68.884), (69.027, 50.51)],
    [1, 0, 0, 1, 0, 0, 0, 0, 0, 0],
    [(0, 1), (0, 2), (0, 6), (1, 2), (1, 4), (1, 5), (1, 6), (2, 7), (3, 4), (3, 5), (4, 8),
     (5, 7), (5, 9), (7, 8), (7, 9)],
    (0, 1), 9,
)  # fmt: skip


@pytest.fixture(scope="module")
def tripod(tmp_path_factory):
    out = tmp_path_factory.mktemp("tripod")
    result, report = export_verified(TRIPOD, out, {"mjcf", "stl"})
    return out, result, report


def test_two_forks_build_what_no_single_fork_does(tripod, monkeypatch, tmp_path):
    monkeypatch.setattr(forked, "MAX_SETS", 0)
    monkeypatch.setattr(strapped, "MAX_STRAPS", 0)  # a turntable with straps builds it too
    monkeypatch.setattr(ground_rings, "MAX_SPLITS", 0)  # and so do ground rings
    monkeypatch.setattr(forked_rings, "MAX_RINGED", 0)  # alone or beside forks
    with pytest.raises(ValueError, match="flat layers"):
        export_mechanism(TRIPOD, tmp_path, {"mjcf"})
    out, result, report = tripod
    assert report.passed, report.failed
    parts = {p["name"]: p for p in result.parts}
    arms: dict[str, list[dict]] = {}
    for part in result.parts:
        if "mesh" in part:
            solid = trimesh.load(out / part["mesh"])
            assert solid.is_watertight and solid.is_volume
        if "arm_of" in part:
            arms.setdefault(part["arm_of"], []).append(part)
    assert set(arms) == {"plate_0_1_2_3", "link_4_5"}
    joints = {name: {j for arm in cut for j in arm["joints"]} for name, cut in arms.items()}
    assert not set.intersection(*joints.values())  # the forks share no joint
    for name, cut in arms.items():
        rods = [p for p in result.parts if p["kind"] == "pin" and p["name"][-1].isalpha()
                and p.get("fixed_in") == name]  # fmt: skip
        shaft = set.intersection(*(set(arm["joints"]) for arm in cut))
        assert shaft - {rod["joints"][0] for rod in rods}  # every arm from an uncut shaft
        assert len(rods) >= 2
        for a, b in combinations(rods, 2):  # rods at one joint stop short of one another
            if a["joints"] == b["joints"]:
                assert a["layers"][1] < b["layers"][0] or b["layers"][1] < a["layers"][0]
    assert parts["pin_0a"]["joins"] == ["plate_0_1_2_3", "ground"]  # the motor drives the crank


def test_forks_round_a_bracket_build_what_no_single_fork_does(monkeypatch, tmp_path):
    monkeypatch.setattr(forked, "MAX_SETS", 0)
    monkeypatch.setattr(braced, "MAX_SPLIT_STRAPS", 0)  # these build it too, without forks
    monkeypatch.setattr(braced, "MAX_CUT_SPLITS", 0)
    monkeypatch.setattr(braced, "MAX_CUT_SCREENED", 0)
    monkeypatch.setattr(ground_rings, "MAX_SPLITS", 0)
    monkeypatch.setattr(forked_rings, "MAX_RINGED", 0)
    with pytest.raises(ValueError, match="flat layers"):
        export_mechanism(BRACED, tmp_path / "refused", {"mjcf"})
    monkeypatch.undo()
    result, report = export_verified(BRACED, tmp_path, {"mjcf", "stl"})
    assert report.passed, report.failed
    parts = {p["name"]: p for p in result.parts}
    assert {p["arm_of"] for p in result.parts if "arm_of" in p} == {"plate_0_1_2_6", "plate_5_7_9"}
    bracket, shaft = parts["ground_bracket0"], parts["pin_0"]
    assert shaft["joins"] == ["ground_bracket0", "plate_0_1_2_6"]
    assert shaft["fixed_in"] == "plate_0_1_2_6"  # the crank's shaft turns in the bracket
    assert shaft["layers"][0] < bracket["layer"] < shaft["layers"][1]  # between its arms
    post = next(p for p in result.parts if p["kind"] == "post")
    assert bracket["layer"] in post["layers"]


def test_the_screened_sets_are_minimal_and_share_no_joint():
    assembly = assemble(TRIPOD)
    sizes = resolve_sizes(TRIPOD, assembly.parts, None)
    union, roles, _, conflicts = swept_candidates(assembly, sweep(TRIPOD, sizes.link_width), sizes)
    bracket = best_brackets(conflicts, roles)
    sets = list(fork_sets(assembly, union, roles, conflicts, forked.drivable, bracket, 3))
    assert sets and len(set(sets)) == len(sets)  # each set found once
    screen = _Screen(assembly, union, roles, conflicts, forked.drivable, bracket)
    taken = {fork: lit for fork, lit in screen.choice.items() if fork[1] is not None}
    taken |= {(0, joint): lit for joint, lit in screen.held.items()}  # the brackets
    with Solver(bootstrap_with=screen.clauses) as solver:
        for forks, held in sets:
            chosen = [*forks, *([(0, held)] if held is not None else [])]
            assert forks and all(forked.drivable(assembly, fork) for fork in forks)
            for (p, _), (q, _) in combinations(forks, 2):
                assert not set(assembly.parts[p].joints) & set(assembly.parts[q].joints)
            off = [-lit for key, lit in taken.items() if key not in chosen]
            assert solver.solve(assumptions=off + [taken[key] for key in chosen])
            for key in chosen:  # none of them can be left out
                assert not solver.solve(assumptions=[*off, -taken[key]])


def test_a_rod_run_through_the_stack_is_caught(tripod, tmp_path):
    """A rod at a joint the link 4-5 carries, stretched from the base to the cover: parts
    pass the joint between the rods there, so verification must name it."""
    tree, geoms = editable_copy(tripod[0], tmp_path)
    rods = sorted(n for n in geoms if n and n.startswith("pin_4") and n[-1].isalpha())
    rod = geoms[rods[0]]
    radius, _ = map(float, rod.get("size").split())
    x, y, _ = map(float, rod.get("pos").split())
    heights = [float(g.get("pos").split()[2]) for g in geoms.values() if g.get("pos")]
    low, high = float(np.min(heights)), float(np.max(heights))
    rod.set("size", f"{radius} {(high - low) / 2}")
    rod.set("pos", f"{x} {y} {(high + low) / 2}")
    assert rods[0] in collision_detail(tree, tmp_path)
