"""The atlas: built deterministically, stored and read back whole, and it finds the
mechanisms whose paths look like a target."""

import time

import numpy as np
import pytest

from linkd.cli import main
from linkd.design.atlas import build, load
from linkd.design.propose import PINNED_POOL, SOURCES, own_frame, place
from linkd.design.refine import RefineSettings
from linkd.errors import InputError
from linkd.validator import validate


@pytest.fixture(scope="module")
def atlas():
    return build(200, seed=5)


def test_build_is_deterministic_and_indexes_moving_joints(atlas):
    again = build(200, seed=5)
    for name in ("positions", "fixed", "links", "mechanism", "joint", "shape", "pivot"):
        assert np.array_equal(getattr(atlas, name), getattr(again, name)), name
    assert len(atlas) > len(atlas.positions)  # several paths per mechanism on average
    whole = atlas.batch(np.arange(len(atlas.positions)))
    assert validate(whole).valid.all()  # every stored mechanism works once rounded
    assert not whole.fixed[np.arange(len(whole))[atlas.mechanism], atlas.joint].any()
    assert (atlas.joint >= 2).all()  # neither the pivot nor the crank tip


def test_saved_atlas_reads_back_and_bad_files_are_refused(atlas, tmp_path):
    atlas.save(tmp_path / "atlas.npz")
    back = load(tmp_path / "atlas.npz")
    assert back.meta == atlas.meta and np.array_equal(back.shape, atlas.shape)
    assert [p.name for p in tmp_path.iterdir()] == ["atlas.npz"]  # no scratch file left
    (tmp_path / "bad.npz").write_text("not an atlas")
    with pytest.raises(InputError, match=r"bad\.npz: not a linkd atlas"):
        load(tmp_path / "bad.npz")
    arrays = dict(np.load(tmp_path / "atlas.npz"))
    arrays["meta"] = np.array('{"format": "linkd-atlas/1"}')
    np.savez(tmp_path / "old.npz", **arrays)
    with pytest.raises(InputError, match=r"old\.npz: a linkd-atlas/1 file, not linkd-atlas/2"):
        load(tmp_path / "old.npz")


def test_a_path_of_the_atlas_is_found_first_and_placed_exactly(atlas):
    entry = 123
    whole = atlas.batch(atlas.mechanism[[entry]])
    motion = validate(whole, n_angles=400, keep_motion=True).motion
    joint = atlas.joint[entry]
    path = np.stack([motion.x[0, joint], motion.y[0, joint]], -1)
    turned = path @ np.array([[0.6, -0.8], [0.8, 0.6]]) * 3.0 + 5.0  # moved, turned, scaled
    found = atlas.nearest(turned[::-1], 5)  # walked backwards too
    same = np.flatnonzero(np.all(atlas.shape == atlas.shape[entry], axis=1))
    assert found[0] in same
    target = (turned - turned.mean(0)) / np.sqrt(((turned - turned.mean(0)) ** 2).sum(1).mean())
    placed = place(atlas.query(target, 5), target)
    assert len(placed) >= 1 and placed.chamfer[0] < 0.02


def test_own_frame_is_blind_to_turning_mirroring_and_scaling_curve_and_point_alike():
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    curve = np.stack([2 * np.cos(t) + 0.3 * np.cos(2 * t), np.sin(t)], -1)  # wide, not symmetric
    point = np.array([0.5, -1.5])
    mirror_turn = np.array([[0.6, 0.8], [0.8, -0.6]])  # a reflection, then scaled and moved
    moved = curve @ mirror_turn * 4.0 + 7.0, point @ mirror_turn * 4.0 + 7.0
    here, there = own_frame(curve[None], point[None]), own_frame(moved[0][None], moved[1][None])
    rms = np.sqrt((curve**2).sum(1).mean())  # the curve is centred on the origin
    assert np.allclose(here, there) and np.allclose(here, [[1.5 / rms, 0.5 / rms]], atol=0.01)


def test_with_a_motor_point_half_the_paths_are_chosen_by_where_their_pivot_sits(atlas):
    """A target that is one of the atlas's paths, turned and scaled, with the motor where that
    path's crank pivot went: half the paths found are the nearest by shape, that path first;
    the other half, of the next paths by shape, those whose pivot lies where the motor lies
    in the target's frame."""
    entry = 123
    whole = atlas.batch(atlas.mechanism[[entry]])
    motion = validate(whole, n_angles=400, keep_motion=True).motion
    joint = atlas.joint[entry]
    path = np.stack([motion.x[0, joint], motion.y[0, joint]], -1)
    turn = np.array([[0.6, -0.8], [0.8, 0.6]]) * 3.0
    target, motor = path @ turn + 5.0, whole.positions[0, 0] @ turn + 5.0
    centre, size = target.mean(0), np.sqrt(((target - target.mean(0)) ** 2).sum(1).mean())
    target, motor = (target - centre) / size, (motor - centre) / size
    found = atlas.nearest(target, 6, motor)
    pool = atlas.nearest(target, 6 * PINNED_POOL)
    assert len(found) == 6 and list(found[:3]) == list(pool[:3])
    assert atlas.pivot[found[0]].tolist() == atlas.pivot[entry].tolist()  # that path, or its twin
    rest = pool[3:]
    off = np.linalg.norm(atlas.pivot[rest].astype(float) - atlas.pivot[entry], axis=1)
    assert set(found[3:]) == set(rest[np.argsort(off)[:3]])  # as near as the f16 pivots say
    assert not set(found[3:]) <= set(pool[:6])  # not simply the next by shape


def test_atlas_build_command(tmp_path, capsys):
    out = tmp_path / "small.npz"
    assert main(["atlas", "build", "--count", "40", "--seed", "1", "--out", str(out)]) == 0
    assert load(out).meta["seed"] == 1 and "mechanisms" in capsys.readouterr().out
    assert main(["atlas", "build", "--count", "0", "--out", str(out)]) == 2
    assert main(["atlas", "build", "--out", str(tmp_path / "no" / "a.npz"), "--count", "5"]) == 2


BRIEF = RefineSettings(iterations=6, ordered_iterations=2, angles=64)


def test_search_combines_the_atlas_with_the_proposer_and_says_what_each_gave(atlas, tmp_path):
    from test_design import options, pool_proposer

    from linkd.constraints import Constraints
    from linkd.curves import normalise, resample
    from linkd.design.search import search as run_search
    from linkd.design.select import end_effector_path
    from linkd.design.stages import Stages
    from linkd.design.stroke import Goal
    from linkd.generator import GeneratorSettings, generate
    from linkd.graph import from_graph

    pool = generate(8, seed=3, settings=GeneratorSettings(min_nodes=5, max_nodes=7)).graphs
    target = normalise(resample(end_effector_path(from_graph(pool[1]), 600)[0], 200))[0]
    atlas.save(tmp_path / "atlas.npz")
    opts = options(atlas=True, atlas_path=str(tmp_path / "atlas.npz"), atlas_paths=32,
                   rounds=2, around=2, around_copies=3, candidates=4, rotations=1,
                   refine_count=6, refine_settings=BRIEF)  # fmt: skip
    search: dict = {}
    found = run_search(Goal(target, True, False), Constraints(), opts, pool_proposer(pool),
                       Stages(False), time.monotonic() + 600, search)  # fmt: skip
    assert set(search["sources"]) == {"model", "atlas", "round 2"}
    assert search["sources"]["atlas"]["placed"] > 0
    for name, figures in search["sources"].items():
        assert np.sum(found.source == SOURCES.index(name)) == figures["placed"]
        assert figures["refined"] <= figures["placed"]
    # Refinement and the later round only improve on what was placed.
    refined = min(f["best_refined"] for f in search["sources"].values() if f["best_refined"])
    assert refined <= min(f["best_placed"] for f in search["sources"].values()) + 1e-9
    assert np.min(found.chamfer) < 0.02  # the curve is one of the pool's paths


def test_a_stroke_is_looked_up_by_its_loop_and_placed_by_its_arc(atlas, tmp_path):
    """An open stroke, most of the revolution of one of the atlas's paths, turned and scaled:
    looked up by the stroke closed by a straight line, that path's mechanism is among those
    found, and placed on the stroke by its sub-arc as well as it can be."""
    from test_design import options, pool_proposer

    from linkd.constraints import Constraints
    from linkd.design.search import search as run_search
    from linkd.design.stages import Stages
    from linkd.design.stroke import make_goal, place_stroke
    from linkd.generator import GeneratorSettings, generate

    entry = 122
    mechanism = atlas.batch(atlas.mechanism[[entry]])
    motion = validate(mechanism, n_angles=400, keep_motion=True).motion
    joint = atlas.joint[entry]
    path = np.stack([motion.x[0, joint], motion.y[0, joint]], -1)
    stroke = path[:340] @ np.array([[0.6, -0.8], [0.8, 0.6]]) * 3.0 + 5.0
    goal = make_goal(stroke, closed=False, timed=False, count=200)[0]
    pool = generate(8, seed=3, settings=GeneratorSettings(min_nodes=5, max_nodes=7)).graphs
    atlas.save(tmp_path / "atlas.npz")
    opts = options(atlas=True, atlas_path=str(tmp_path / "atlas.npz"), atlas_paths=32,
                   candidates=4, rotations=1, refine=False)  # fmt: skip
    search: dict = {}
    run_search(goal, Constraints(), opts, pool_proposer(pool), Stages(False),
               time.monotonic() + 600, search)  # fmt: skip
    # As well placed as the path's own mechanism (the score's floor: 64 points a curve).
    own = place_stroke(mechanism.sub_mechanisms(np.arange(1), np.array([joint])), goal).chamfer
    assert search["sources"]["atlas"]["best_placed"] <= own[0] + 1e-6
    assert search["sources"]["model"]["best_placed"] > 2 * own[0]  # the pool holds no such path
