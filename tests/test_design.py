"""`linkd design`: placing candidates on the user's curve, the staged run, its output folder.

Candidates come from the curated random generator here (a stand-in for LinkD that needs no
checkpoint); the run with the shipped model is in test_design_cli.py.
"""

import json
import os

import numpy as np
import pytest

from linkd import classic
from linkd.batch import LinkageBatch, ancestors
from linkd.curves import normalise, read_curve, resample, write_curve
from linkd.design.pipeline import DesignOptions, design
from linkd.design.propose import augmented, place, sub_mechanisms
from linkd.design.refine import RefineSettings
from linkd.design.select import curve_error, end_effector_path, topology_key
from linkd.geometry import Similarity, rotation
from linkd.graph import from_graph, to_graph
from linkd.mechanism import Mechanism
from linkd.validator import validate

# The user's frame: millimetres, turned, mirrored and moved away from the origin.
USER = Similarity(40.0, rotation(0.7, reflect=True), np.array([100.0, -20.0]))
QUICK = RefineSettings(iterations=20, ordered_iterations=5)


@pytest.fixture(scope="module")
def curve_file(pool, tmp_path_factory):
    """The path of the pool's first mechanism, in the user's frame, as a curve CSV."""
    path = end_effector_path(from_graph(pool[0]), 1000)[0]
    file = tmp_path_factory.mktemp("curves") / "loop.csv"
    write_curve(file, USER.apply(resample(path, 150)))
    return file


def pool_proposer(pool):
    """Proposes the pool's graphs (shuffled by seed), whatever the curves."""

    def propose(curves, per_curve, seed):
        order = np.random.default_rng(seed).permutation(len(pool))
        return pool[np.resize(order, len(curves) * per_curve)]

    return propose


def options(**changes) -> DesignOptions:
    settings = dict(
        candidates=12,
        time_budget=600,
        refine_settings=QUICK,
        formats={"mjcf"},
        atlas=False,
        rounds=1,
    )  # the atlas and later rounds: test_atlas.py
    return DesignOptions(**{**settings, **changes})


def test_placing_recovers_a_known_similarity(pool, curve_file):
    target, frame = normalise(resample(read_curve(curve_file), 200))
    placed = place(LinkageBatch.from_graphs(pool[:1]), target)
    assert len(placed) == 1 and placed.chamfer[0] < 0.01
    # The true transform from the graph's frame to the target's normalised frame:
    truth = USER.then(frame.inverse())
    expected = truth.apply(from_graph(pool[0]).positions)
    n = len(expected)
    error = np.abs(placed.batch.positions[0, :n] - expected).max()
    assert error < 0.01 * np.abs(expected).max()


def test_every_moving_joint_offers_a_valid_sub_mechanism_tracing_its_path():
    jansen = LinkageBatch.from_mechanisms([classic.jansen_leg()])
    full = validate(jansen, keep_motion=True)
    target = np.stack([np.cos(np.linspace(0, 6, 200)), np.sin(np.linspace(0, 6, 200))], 1)
    subs = sub_mechanisms(jansen, target, keep=100)
    moving = (~jansen.fixed[0] & jansen.valid[0]).sum() - 1  # all but the crank tip
    assert len(subs) == moving
    result = validate(subs, keep_motion=True)
    assert result.valid.all()
    paths = result.end_effector_paths(subs)
    joints = {int(k) for k in subs.valid.sum(1)}
    assert min(joints) == 4 and max(joints) == jansen.valid[0].sum()  # four-bars up to the leg
    # Each sub-mechanism's end effector follows one joint of the leg exactly.
    leg = full.motion.paths[0]  # (N, T, 2)
    gaps = np.abs(paths[:, None] - leg[None]).max((2, 3)).min(1)
    assert gaps.max() < 1e-9
    # Asking for fewer keeps the ones whose shape is closest to the target's.
    assert len(sub_mechanisms(jansen, target, keep=3)) == 3


def test_augmented_copies_are_turned_and_mirrored():
    target = normalise(resample(classic_path(), 200))[0]
    copies = augmented(target, 4)
    assert copies.shape == (8, 200, 2)
    np.testing.assert_allclose(copies[0], target)
    np.testing.assert_allclose(copies[1], target @ rotation(np.pi / 2).T)
    np.testing.assert_allclose(copies[4], (target @ rotation(0, reflect=True).T)[::-1])


def classic_path() -> np.ndarray:
    return end_effector_path(classic.crank_rocker(), 400)[0]


def test_design_writes_a_verified_export_on_the_users_curve(pool, curve_file, tmp_path):
    out = tmp_path / "loop-design"
    opts = options(top=1, formats={"mjcf", "stl"})
    outcome = design(curve_file, out, opts, proposer=pool_proposer(pool), show=False)
    assert outcome.design is not None
    names = {p.name for p in out.iterdir()}
    assert {"mechanism.json", "mechanism.xml", "scene.xml", "meshes", "animation.html",
            "curve.png", "report.json"} <= names  # fmt: skip
    assert list((out / "meshes").glob("*.stl"))
    umask = os.umask(0)
    os.umask(umask)
    for path in [out, *out.rglob("*")]:  # ordinary files and folders, as the umask makes them
        assert path.stat().st_mode & 0o777 == (0o777 if path.is_dir() else 0o666) & ~umask, path
    report = json.loads((out / "report.json").read_text())
    assert report["verification"]["passed"]
    assert report["export"]["sizes"] == outcome.design.export.sizes  # what built it
    search = report["search"]  # the pool's designs are all valid; each offers sub-mechanisms
    assert search["proposed"] == search["valid"] < search["placed"]
    assert {"read_s", "propose_s", "align_s", "refine_s", "verify_s", "write_s", "total_s"} <= set(
        report["timings"]
    )
    assert report["design"]["nodes"] == outcome.design.mechanism.n_nodes
    # The design sits on the user's curve, in the user's frame and units.
    mech = Mechanism.load(out / "mechanism.json")
    assert mech.units == "mm" and {"metrics", "source", "layers", "parts"} <= set(mech.extra)
    target = read_curve(curve_file)
    assert curve_error(end_effector_path(mech)[0], target) < 0.01
    assert mech.extra["metrics"]["chamfer"] == pytest.approx(report["design"]["chamfer"])
    # Every joint carries the end effector (what growth leaves behind is pruned).
    delivered = LinkageBatch.from_mechanisms([mech])
    assert ancestors(delivered.adjacency, delivered.end_effector).all()
    # One alternative, of another topology, verified as well.
    (alt,) = report["alternatives"]
    alt_mech = Mechanism.load(out / alt["folder"] / "mechanism.json")
    keys = {topology_key(LinkageBatch.from_mechanisms([m]), 0) for m in (mech, alt_mech)}
    assert len(keys) == 2 and alt["verified"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no staging left


def test_design_is_deterministic_for_a_seed(pool, curve_file, tmp_path):
    texts = []
    for name in ("a", "b"):
        outcome = design(curve_file, tmp_path / name, options(seed=5),
                         proposer=pool_proposer(pool), show=False)  # fmt: skip
        assert outcome.design is not None
        texts.append((tmp_path / name / "mechanism.json").read_text())
    assert texts[0] == texts[1]


def test_rounds_and_polish_the_deadline_cuts_are_reported(pool, curve_file, tmp_path, monkeypatch):
    """Every refinement runs in full here, but the clock says the deadline has passed before
    the later rounds and the polish: the run then depends on the machine's speed, and says so."""
    import time
    import types

    from linkd.design import search

    out = []
    for name, clock in (("on time", time.monotonic), ("late", lambda: float("inf"))):
        monkeypatch.setattr(search, "time", types.SimpleNamespace(monotonic=clock))
        outcome = design(curve_file, tmp_path / name, options(rounds=3, atlas=False),
                         proposer=pool_proposer(pool), show=False)  # fmt: skip
        out.append(outcome.report["search"])
    assert out[0]["rounds_run"] == 3 and not out[0]["budget_cut_refinement"]
    assert sum(source["refined"] for source in out[0]["sources"].values()) == out[0]["refined"]
    assert out[1]["rounds_run"] == 1 and out[1]["budget_cut_refinement"]
    assert out[1]["refine_iterations"] == QUICK.iterations  # the first refinement was whole


def test_a_slow_first_refinement_leaves_the_later_rounds_their_share(pool, curve_file, tmp_path,
                                                                    monkeypatch):  # fmt: skip
    """On a machine so slow that one refinement step takes a second of a 26 s search, the
    first refinement alone would fill the search (and leave no later round): it stops at its
    share of the time, and a later round runs."""
    import time
    import types

    from linkd.design import lbfgs, parallel

    clock = [0.0]

    def step_taken() -> float:
        clock[0] += 1.0
        return clock[0]

    monkeypatch.setattr(time, "monotonic", lambda: clock[0])  # time passes only in L-BFGS steps
    monkeypatch.setattr(lbfgs, "time", types.SimpleNamespace(monotonic=step_taken))
    monkeypatch.setattr(parallel, "can_fork", lambda: False)  # one process, one clock
    slow = RefineSettings(iterations=40, ordered_iterations=5)
    outcome = design(curve_file, tmp_path / "slow", options(rounds=3, time_budget=38.0,
                     refine_settings=slow), proposer=pool_proposer(pool), show=False)  # fmt: skip
    report = outcome.report["search"]
    assert report["refine_iterations"] < slow.iterations and report["budget_cut_refinement"]
    assert report["rounds_run"] >= 2 and outcome.design is not None


def test_design_does_not_depend_on_a_second_process(pool, curve_file, tmp_path, monkeypatch):
    """Proposal and refinement run in two parts at once where they can, one after the other
    where they cannot (`linkd.design.parallel`): the same design either way."""
    from linkd.design import parallel

    texts = []
    for name, fork in (("both", True), ("alone", False)):
        monkeypatch.setattr(parallel, "can_fork", lambda fork=fork: fork)
        outcome = design(curve_file, tmp_path / name, options(seed=2),
                         proposer=pool_proposer(pool), show=False)  # fmt: skip
        assert outcome.design is not None
        texts.append((tmp_path / name / "mechanism.json").read_text())
    assert texts[0] == texts[1]


def test_unrefined_single_sample_is_only_placed(pool, curve_file, tmp_path):
    """The one-shot setting: one sample, no refinement, only moved onto the curve."""
    single = options(candidates=1, refine=False, rotations=0, attempts=1)
    outcome = design(curve_file, tmp_path / "one", single,
                     proposer=lambda curves, k, seed: pool[:1], show=False)  # fmt: skip
    assert outcome.design is not None and outcome.report["search"]["refined"] == 0
    assert outcome.report["search"]["skipped"] == {"invalid": 0, "unbuildable": 0,
                                                   "failed_verification": 0}  # fmt: skip
    sample = from_graph(pool[0])
    lengths = outcome.design.mechanism.link_lengths()
    ratio = lengths / sample.link_lengths()
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-6)  # the same linkage, only scaled


def test_no_valid_design_writes_nothing(tmp_path, curve_file):
    locked = np.stack([to_graph(classic.non_grashof_four_bar())[0]] * 3)
    outcome = design(curve_file, tmp_path / "out", options(),
                     proposer=lambda curves, k, seed: locked, show=False)  # fmt: skip
    assert outcome.design is None and outcome.out is None
    assert list(tmp_path.iterdir()) == []


def test_interruption_leaves_no_output(tmp_path, curve_file):
    def interrupted(curves, per_curve, seed):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        design(curve_file, tmp_path / "out", options(), proposer=interrupted, show=False)
    assert list(tmp_path.iterdir()) == []
