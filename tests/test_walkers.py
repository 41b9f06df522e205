"""Jansen walkers (linkd.classic.jansen_walker): the multi-leg mechanisms a user brings, built
as a Strandbeest is: a mirrored pair of legs, and three pairs on three crank pins between
frame plates (linkd.export.framed), exported and verified, and a frame moved into a module
caught."""

import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import trimesh

from linkd.classic import jansen_leg, jansen_walker
from linkd.commands.export import _counts
from linkd.export import export_mechanism
from linkd.export.framed import framed_layers
from linkd.export.layers import sweep
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.mechanism import UNITS_IN_METRES, Mechanism
from linkd.topology import Status
from linkd.validator import validate_mechanism
from linkd.verify import verify_output

STRANDBEEST = Path(__file__).parents[1] / "assets" / "examples" / "strandbeest.json"


def test_one_leg_is_jansens_leg():
    assert np.array_equal(jansen_walker(1, mirrored=False).positions, jansen_leg().positions)


@pytest.mark.parametrize("phases, mirrored, joints", [(1, True, 14), (3, False, 20), (3, True, 36)])
def test_walkers_turn_fully_with_every_leg_on_the_crank(phases, mirrored, joints):
    walker = jansen_walker(phases, mirrored)
    assert walker.n_nodes == joints and validate_mechanism(walker)[0] == Status.VALID
    pins = {j for link in walker.links if 0 in link for j in link} - {0}
    assert len(pins) == phases  # every crank pin on the axle, as one plate
    foot = walker.positions[walker.end_effector]  # the first leg's; its mirror's, 5 joints on
    assert not mirrored or np.allclose(walker.positions[walker.end_effector + 5], foot * [-1, 1])


def test_an_even_number_of_crank_pins_is_refused():
    with pytest.raises(ValueError, match="odd number of pins, got 2"):
        jansen_walker(2)


def test_a_mirrored_pair_of_legs_is_built_and_verified(tmp_path):
    result = export_mechanism(jansen_walker(1, mirrored=True), tmp_path, {"mjcf", "stl"})
    assert sum(part["kind"] == "pin" for part in result.parts) == 12
    report = verify_output(tmp_path, write=False)
    assert report.passed, report.failed


@pytest.fixture(scope="module")
def three_pairs(tmp_path_factory):
    out = tmp_path_factory.mktemp("walker")
    return out, export_mechanism(Mechanism.load(STRANDBEEST), out, {"mjcf", "stl"})


def test_the_shipped_strandbeest_is_three_mirrored_pairs():
    shipped, walker = Mechanism.load(STRANDBEEST), jansen_walker(3, mirrored=True)
    assert np.allclose(shipped.positions, walker.positions) and shipped.links == walker.links


def test_three_mirrored_pairs_are_built_between_frames_and_verified(three_pairs):
    out, result = three_pairs
    parts = {part["name"]: part for part in result.parts}
    floors = [0, *sorted(parts[f"ground_frame{k}"]["layer"] for k in range(2)), result.layers - 1]
    arms = [part for part in result.parts if part.get("arm_of") == "plate_0_1_14_25"]
    assert len(arms) == 5  # two per pair but the top one's
    for pin, lo, hi in zip((1, 14, 25), floors, floors[1:]):  # each pair in a storey of its own
        mine = sorted(arm["layer"] for arm in arms if pin in arm["joints"])
        legs = [
            part["layer"]
            for part in result.parts
            if part["kind"] != "pin" and pin in part.get("joints", ()) and part not in arms
        ]
        assert lo < mine[0] < min(legs) and max(legs) < hi
        assert parts[f"pin_{pin}"]["layers"] == [mine[0], max(mine[1:] or legs)]
        assert len(mine) == 1 or max(legs) < mine[1]  # the legs between the two arms
    # the motor's pin: journals fixed in the crank, from the base and through each frame
    journals = [parts[f"pin_0{letter}"] for letter in "abc"]
    spans = [journal["layers"] for journal in journals]
    assert spans[0][0] == 0 and all(lo < at < hi for (lo, hi), at in zip(spans[1:], floors[1:]))
    assert all(j["fixed_in"] == "plate_0_1_14_25" for j in journals) and "pin_0d" not in parts
    posts = [part for part in result.parts if part["kind"] == "post"]
    assert len(posts) == 3 and all(post["layers"] == [0, result.layers - 1] for post in posts)
    for name in ("ground", "ground_frame0", "ground_frame1", "ground_cover"):
        assert trimesh.load(out / parts[name]["mesh"]).is_watertight
    report = verify_output(out, write=False)
    assert report.passed, report.failed


def test_the_export_summary_counts_the_cranks_arms_as_arms(three_pairs):
    _, result = three_pairs
    counts = _counts(result.parts)  # the crank's five arms, not five more plates
    assert counts["arm"] == 5 and sum(counts.values()) == len(result.parts)
    assert counts["plate"] == 12  # the legs' own: two ternary plates in each of the six


def test_a_frame_moved_into_a_module_is_caught(three_pairs, tmp_path):
    out, result = three_pairs
    folder = tmp_path / "out"
    shutil.copytree(out, folder)
    tree = ET.parse(folder / "mechanism.xml")
    frame = next(g for g in tree.getroot().iter("geom") if g.get("name") == "ground_frame0")
    x, y, z = map(float, frame.get("pos").split())
    pitch = (result.sizes["thickness"] + result.sizes["layer_gap"]) * UNITS_IN_METRES["mm"]
    frame.set("pos", f"{x} {y} {z - pitch}")  # onto the first pair's upper arm
    tree.write(folder / "mechanism.xml")
    report = verify_output(folder, write=False)
    assert not report.passed and "collisions" in report.failed


def test_a_mechanism_not_made_of_modules_is_not_framed():
    leg = jansen_leg()  # every part joined to the others away from the ground and the crank
    assembly, sizes = assemble(leg), resolve_sizes(leg, assemble(leg).parts, None)
    with pytest.raises(ValueError, match="not modules on one crank"):
        framed_layers(assembly, sweep(leg, sizes.link_width), sizes)
