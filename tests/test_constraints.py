"""Designer's constraints: parsing and refusals, the exact check, `linkd validate` with them, and
a constrained design run (candidates from the random generator, as in test_design.py)."""

import argparse
import json
from functools import partial

import numpy as np
import pytest
import torch

from linkd import classic, constraints
from linkd.batch import LinkageBatch
from linkd.cli import main
from linkd.constraints import Box, Constraints, check, measure_batch
from linkd.curves import normalise, read_curve, resample, write_curve
from linkd.design.constrained import SOFT, pin, pinned, screen
from linkd.design.pipeline import DesignOptions, design
from linkd.design.propose import Candidates, own_frame, sub_mechanisms
from linkd.design.refine import RefineSettings, resample_closed
from linkd.design.select import curve_error, end_effector_path
from linkd.export import export_mechanism
from linkd.generator import GeneratorSettings, generate
from linkd.geometry import Similarity, rotation
from linkd.graph import from_graph
from linkd.kinematics import trace
from linkd.mechanism import Mechanism
from linkd.topology import assembly_plan
from linkd.validator import validate


def parse(**given) -> Constraints:
    names = dict.fromkeys(constraints.OPTIONS)
    return constraints.from_args(argparse.Namespace(**{**names, **given}))


def test_options_parse_in_the_curves_units():
    c = parse(motor_at="-5,3", ground_box="-10,-10,10,5", envelope="-50,-40,60,70",
              min_link="2.5", max_joints="8", min_transmission="20")  # fmt: skip
    assert c.motor_at == (-5.0, 3.0) and c.ground_box == Box(-10, -10, 10, 5)
    assert (c.min_link, c.max_joints, c.min_transmission) == (2.5, 8, 20.0)
    assert c.given() == list(constraints.OPTIONS) and not parse()
    # Into another frame: lengths scale, angles and counts do not.
    moved = c.mapped(Similarity(2.0, np.eye(2), np.array([1.0, 0.0])))
    assert moved.motor_at == (-9.0, 6.0) and moved.envelope == Box(-99, -80, 121, 140)
    assert (moved.min_link, moved.max_joints, moved.min_transmission) == (5.0, 8, 20.0)


@pytest.mark.parametrize(
    "given, words",
    [
        (dict(envelope="5,0,1,1"), "--envelope"),
        (dict(ground_box="0,5,1,1"), "--ground-box"),
        (dict(ground_box="0,0,1"), "--ground-box"),
        (dict(min_link="-3"), "--min-link"),
        (dict(min_link="nan"), "--min-link"),
        (dict(motor_at="a,b"), "--motor-at"),
        (dict(motor_at="1,2,3"), "--motor-at"),
        (dict(max_joints="7.5"), "--max-joints"),
        (dict(max_joints="2"), "--max-joints"),
        (dict(min_transmission="95"), "--min-transmission"),
        (dict(motor_at="20,0", ground_box="-10,-10,10,10"), "outside the ground box"),
        (dict(motor_at="0,0", envelope="1,1,2,2"), "outside the envelope"),
        (dict(ground_box="0,0,1,1", envelope="2,2,3,3"), "do not overlap"),
    ],
)
def test_bad_constraints_are_refused_with_one_line(given, words):
    with pytest.raises(constraints.InputError) as refused:
        parse(**given)
    message = str(refused.value)
    assert words in message and "\n" not in message


def dense(mech: Mechanism, angles: int = 200_000):
    """Joint paths (N, T, 2) and worst transmission sine^2 at many crank angles."""
    batch = LinkageBatch.from_mechanisms([mech])
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    motion = trace(batch.positions, plan, angles)
    return motion.paths[0], float(motion.margin[0])


def test_check_measures_each_constraint_exactly():
    mech = classic.crank_rocker().transformed(Similarity(10.0, rotation(0.3), np.array([5, 7.0])))
    paths, margin = dense(mech)
    low, high = paths.reshape(-1, 2).min(0), paths.reshape(-1, 2).max(0)
    worst = np.degrees(np.arcsin(np.sqrt(margin)))
    pivot = mech.positions[0]
    fixed = mech.positions[mech.fixed]
    c = Constraints(
        motor_at=tuple(pivot),
        ground_box=Box(*(fixed.min(0) - 1), *(fixed.max(0) + 2)),
        envelope=Box(*(low - 3), *(high + 4)),
        min_link=9.0,
        max_joints=5,
        min_transmission=worst - 1,
    )
    got = {m.name: m for m in check(mech, c)}
    assert all(m.holds for m in got.values())
    assert got["motor_at"].margin == 0 and got["max_joints"].margin == 0
    assert got["ground_box"].margin == pytest.approx(1.0)
    assert got["min_link"].value == pytest.approx(mech.link_lengths().min())
    # The extremes over the revolution, not only at sampled angles: at least as far out as
    # 200,000 samples, and no further than the sampling could miss.
    assert got["envelope"].margin == pytest.approx(3.0, abs=1e-6)
    assert got["envelope"].margin <= 3.0 + 1e-12
    bounds = np.array(got["envelope"].value)
    np.testing.assert_allclose(bounds, [*low, *high], atol=1e-6)
    assert got["min_transmission"].value == pytest.approx(worst, abs=1e-4)
    assert got["min_transmission"].value <= worst + 1e-9
    # Each one fails when the limit is moved past what the mechanism has.
    tight = Constraints(
        motor_at=(pivot[0] + 0.5, pivot[1]),
        ground_box=Box(*(fixed.min(0) + 0.1), *(fixed.max(0) + 2)),
        envelope=Box(*(low + 0.01), *(high + 4)),
        min_link=mech.link_lengths().min() + 0.01,
        max_joints=4,
        min_transmission=worst + 0.01,
    )
    failed = check(mech, tight)
    assert not any(m.holds for m in failed)
    assert {m.name: m.margin for m in failed}["motor_at"] == pytest.approx(-0.5)


def test_batched_screening_matches_the_exact_check():
    mechs = [classic.crank_rocker(), classic.jansen_leg(), classic.watt_six_bar()]
    c = Constraints((0.0, 0.0), Box(-100, -100, 100, 100), Box(-5, -5, 5, 5), 1.0, 6, 10.0)
    batched = measure_batch(LinkageBatch.from_mechanisms(mechs), c, 720)
    for row, mech in enumerate(mechs):
        for m in check(mech, c):
            tolerance = 1e-3 * (1 + abs(m.margin))
            assert batched[m.name][1][row] == pytest.approx(m.margin, abs=tolerance)


def test_max_joints_prunes_sub_mechanisms_before_ranking():
    jansen = LinkageBatch.from_mechanisms([classic.jansen_leg()])
    target = np.stack([np.cos(np.linspace(0, 6, 200)), np.sin(np.linspace(0, 6, 200))], 1)
    subs = sub_mechanisms(jansen, target, keep=100, max_joints=6)
    assert len(subs) > 0 and subs.valid.sum(1).max() <= 6


def test_validate_checks_constraints(tmp_path, capsys):
    file = tmp_path / "m.json"
    classic.crank_rocker().save(file)
    assert main(["validate", str(file), "--envelope=-5,-5,10,10", "--max-joints", "5"]) == 0
    said = capsys.readouterr().out
    assert "constraints hold" in said and "worst transmission angle" in said
    assert main(["validate", str(file), "--envelope", "-1,-1,1,1", "--min-link", "2.5"]) == 1
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and "--envelope" in out[0] and "--min-link" in out[0]
    assert main(["validate", str(file), "--motor-at", "-5,3"]) == 1  # a negative value parses
    assert "--motor-at" in capsys.readouterr().out
    for bad in (["--ground-box", "5,0,1,1"], ["--min-link", "-1"], ["--motor-at", "x,1"]):
        assert main(["validate", str(file), *bad]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_design_refuses_bad_constraints_and_writes_nothing(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    curve = tmp_path / "c.csv"
    write_curve(curve, np.stack([np.cos(np.arange(20) / 3), np.sin(np.arange(20) / 3)], 1))
    for bad in (["--envelope", "5,0,1,1"], ["--motor-at", "9,9", "--ground-box", "0,0,1,1"],
                ["--max-joints", "many"]):  # fmt: skip
        assert main(["design", str(curve), *bad]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert [p.name for p in tmp_path.iterdir()] == ["c.csv"]


# ---- a constrained design run ---------------------------------------------------------------

USER = Similarity(40.0, rotation(0.7, reflect=True), np.array([100.0, -20.0]))


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A small exportable generated mechanism (in the user's frame), its graph pool, and its
    path written as the user's curve."""
    graphs = generate(12, seed=3, settings=GeneratorSettings(min_nodes=5, max_nodes=7)).graphs
    for k, graph in enumerate(graphs):
        mech = from_graph(graph, USER)
        try:
            export_mechanism(mech, tmp_path_factory.mktemp("export"), set())
        except ValueError:
            continue
        pool = np.concatenate([graphs[k:], graphs[:k]])
        file = tmp_path_factory.mktemp("curves") / "loop.csv"
        write_curve(file, resample(end_effector_path(mech, 1000)[0], 150))
        return mech, pool, file
    raise AssertionError("no exportable design in the pool")


def run(pool, curve, out, limits: Constraints, refine: bool = True, atlas: bool = True):
    """A constrained design run; with the atlas, its 128 paths nearest the curve."""

    def propose(curves, per_curve, seed):
        order = np.random.default_rng(seed).permutation(len(pool))
        return pool[np.resize(order, len(curves) * per_curve)]

    quick = RefineSettings(iterations=20, ordered_iterations=5)
    opts = DesignOptions(candidates=12, time_budget=600, refine_settings=quick, refine=refine,
                         formats=frozenset({"mjcf"}), constraints=limits, rounds=2,
                         atlas=atlas, atlas_paths=128)  # fmt: skip
    return design(curve, out, opts, proposer=propose, show=False)


def test_constrained_design_meets_every_constraint(small, tmp_path):
    mech, pool, curve = small
    paths, margin = dense(mech, 2000)
    sweep = paths.reshape(-1, 2)
    size = np.ptp(sweep, 0).max()
    fixed = mech.positions[mech.fixed]
    limits = Constraints(
        motor_at=tuple(mech.positions[0]),
        ground_box=Box(*(fixed.min(0) - size / 5), *(fixed.max(0) + size / 5)),
        envelope=Box(*(sweep.min(0) - size / 2), *(sweep.max(0) + size / 2)),
        min_link=0.5 * mech.link_lengths().min(),
        max_joints=mech.n_nodes,
        min_transmission=0.5 * np.degrees(np.arcsin(np.sqrt(margin))),
    )
    outcome = run(pool, curve, tmp_path / "out", limits)
    assert outcome.design is not None
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    listed = {m["name"]: m for m in report["constraints"]}
    assert set(listed) == set(limits.given()) and all(m["holds"] for m in listed.values())
    assert all(m["margin"] >= 0 for m in listed.values())
    delivered = Mechanism.load(tmp_path / "out" / "mechanism.json")
    assert tuple(delivered.positions[delivered.motor[0]]) == limits.motor_at  # exactly
    assert all(m.holds for m in check(delivered, limits))
    assert curve_error(end_effector_path(delivered)[0], read_curve(curve)) < 0.02


def test_no_design_within_an_envelope_names_it_and_writes_nothing(small, tmp_path):
    mech, pool, curve = small
    pivot = mech.positions[0]
    cramped = Box(*(pivot - 0.01), *(pivot + 0.01))
    # Without the atlas: the refusal is the same, and its paths take most of a minute to check.
    outcome = run(pool, curve, tmp_path / "out", Constraints(envelope=cramped), refine=False,
                  atlas=False)  # fmt: skip
    assert outcome.design is None
    reason = outcome.report["reason"]
    assert reason.startswith("no design keeps every joint inside the envelope")
    assert "sweep" in reason
    assert list(tmp_path.iterdir()) == []


def test_bench_setup_is_consistent_around_a_curve():
    """The benchmark's constraints: motor below the curve, inside the ground box and the
    envelope; the ground box under the curve; the curve inside the envelope."""
    from linkd.design.bench import constraint_setup

    curve = 100 * np.stack([np.cos(np.arange(50) / 8), 0.5 * np.sin(np.arange(50) / 8)], 1)
    c = constraint_setup(curve)
    motor = np.array(c.motor_at)
    assert motor[1] < curve[:, 1].min()
    assert c.ground_box.margin(motor) > 0 and c.envelope.margin(motor) > 0
    assert c.ground_box.y1 < curve[:, 1].min() and (c.envelope.margin(curve) > 0).all()


def test_the_screen_leaves_a_pivot_off_the_motor_point_where_it_is():
    mech = classic.crank_rocker()
    batch = LinkageBatch.from_mechanisms([mech, mech.replace(positions=mech.positions + 0.5)])
    feasible, measured = screen(batch, Similarity(), Constraints(motor_at=(0.0, 0.0)))
    assert feasible.tolist() == [True, False]
    assert measured["motor_at"][1][1] == pytest.approx(-0.5 * np.sqrt(2))


def test_a_ground_box_alone_pins_each_crank_pivot_outside_it_at_its_nearest_point():
    """Without a motor point, placement moves each crank pivot that lies outside the ground box
    to the box's nearest point (SOFT inside), the rest of its mechanism turned and scaled about
    it to fit the path; a candidate whose pivot is inside stays as placed."""
    mech = classic.crank_rocker()
    path = end_effector_path(mech, 200)[0]
    away = mech.replace(positions=mech.positions + np.array([3.0, 0.0]))
    batch = LinkageBatch.from_mechanisms([away, mech])
    pivot = mech.positions[0]
    box = Box(*(pivot - 1), *(pivot + 1))
    placed = Candidates(batch, np.array([0.5, 0.0]), source=np.arange(2))
    moved = pinned(placed, Constraints(ground_box=box), partial(pin, target=path))
    assert moved.source.tolist() == [1, 0]
    assert np.array_equal(moved.batch.positions[0], mech.positions)  # as placed
    assert moved.batch.positions[1, 0].tolist() == [box.x1 - SOFT, pivot[1]]  # exactly there
    assert moved.chamfer[1] < 0.5  # fitted about it
    unpinned = pinned(placed, Constraints(min_link=0.1), partial(pin, target=path))
    assert unpinned is placed


def test_pinning_a_batch_places_each_candidate_as_it_would_be_placed_alone():
    """`pin` works in two parts at once: each candidate still gets the placement it gets alone
    (about its own motor point), and the batch comes back sorted by the new error."""
    mech = classic.crank_rocker()
    path = end_effector_path(mech, 200)[0]
    pivot = mech.positions[0]
    turns = ((0.0, 1.0), (0.4, 1.3), (-1.0, 0.7), (2.5, 1.1), (0.2, 0.5))  # angle, scale
    copies = [mech.replace(positions=pivot + (mech.positions - pivot) @ rotation(a).T * s)
              for a, s in turns]  # fmt: skip
    batch = LinkageBatch.from_mechanisms(copies)
    motor = pivot + np.arange(5)[:, None] * np.array([0.05, -0.02])  # one point each
    together = pin(Candidates(batch, np.zeros(5), source=np.arange(5)), path, motor)
    assert np.all(np.diff(together.chamfer) >= 0) and sorted(together.source) == list(range(5))
    for row, k in enumerate(together.source):
        alone = pin(Candidates(batch.subset([k]), np.zeros(1), source=np.array([k])), path,
                    motor[k : k + 1])  # fmt: skip
        assert together.batch.positions[row, 0].tolist() == motor[k].tolist()
        assert np.allclose(together.batch.positions[row], alone.batch.positions[0], atol=1e-9)
        assert together.chamfer[row] == pytest.approx(alone.chamfer[0], abs=1e-9)


def test_with_a_motor_point_sub_mechanisms_whose_pivot_sits_there_are_offered():
    """Half the sub-mechanisms offered are the nearest by shape, as without a motor point; the
    other half lie nearer it, their pivots where the motor sits in the target's own frame."""
    pool = LinkageBatch.from_graphs(generate(60, seed=2, settings=GeneratorSettings(5, 8)).graphs)
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    target = np.stack([np.cos(t), 0.5 * np.sin(t) + 0.2 * np.cos(2 * t)], 1)
    target = normalise(target)[0]
    motor = np.array([0.3, -2.0])

    def offsets(subs: LinkageBatch) -> np.ndarray:
        result = validate(subs, keep_motion=True)
        curves = resample_closed(torch.as_tensor(result.end_effector_paths(subs)), 64).numpy()
        want = own_frame(resample_closed(torch.as_tensor(target)[None], 64).numpy(), motor[None])
        return np.linalg.norm(own_frame(curves, subs.positions[:, 0]) - want, axis=1)

    plain = sub_mechanisms(pool, target, keep=8)
    by_pivot = sub_mechanisms(pool, target, keep=8, motor=motor)
    shared = {p.tobytes() for p in plain.positions} & {p.tobytes() for p in by_pivot.positions}
    assert len(by_pivot) == 8 and len(shared) >= 4  # the nearest half by shape kept
    assert np.sort(offsets(by_pivot))[:4].mean() < np.sort(offsets(plain))[:4].mean()
