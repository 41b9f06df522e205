"""Open paths and timing: what a target means (open or closed, timed), the crank range in
mechanism.json, and designs recovering a known mechanism's stroke, range and timing.

Candidates come from a small pool of generated designs (a stand-in for LinkD that needs no
checkpoint), among them the mechanism whose path is the target.
"""

import json

import numpy as np
import pytest
from test_design import pool_proposer

from linkd import classic
from linkd.cli import main
from linkd.constraints import Constraints
from linkd.curves import resample, write_curve
from linkd.design.bench import run_bench
from linkd.design.pipeline import DesignOptions, design
from linkd.design.refine import RefineSettings
from linkd.design.select import end_effector_path, timing_of
from linkd.errors import InputError
from linkd.geometry import Similarity, rotation
from linkd.graph import from_graph
from linkd.mechanism import Mechanism
from linkd.paths import checked_path, is_closed

USER = Similarity(30.0, rotation(0.4), np.array([50.0, 10.0]))
QUICK = RefineSettings(iterations=30, ordered_iterations=10)


def arc(turn: float, n: int = 60) -> np.ndarray:
    t = np.linspace(0, turn, n)
    return np.stack([np.cos(t), np.sin(t)], 1)


def test_open_and_closed_paths_are_told_apart():
    assert not is_closed(arc(4.0))  # a C: its ends far apart
    assert is_closed(arc(2 * np.pi, 200)[:-1])  # a loop, last point not repeated
    assert is_closed(arc(2 * np.pi, 9)[:-1])  # a coarse loop: the gap is one of its steps
    assert not is_closed(np.stack([np.linspace(0, 1, 50), np.zeros(50)], 1))  # a line
    # --path open / closed override the guess; a repeated first point says closed.
    assert checked_path("c.csv", arc(4.0), "closed")[1]
    assert not checked_path("o.csv", arc(2 * np.pi, 100)[:-1], "open")[1]
    loop = arc(2 * np.pi, 100)[:-1]
    loop = np.vstack([loop, loop[:1]])
    points, closed = checked_path("r.csv", loop, "auto")
    assert closed and len(points) == 99


def test_bad_paths_are_refused():
    line = np.stack([np.linspace(0, 1, 50), 2 * np.linspace(0, 1, 50)], 1)
    assert not checked_path("line.csv", line, "open")[1]  # a straight stroke is fine ...
    with pytest.raises(InputError, match="one line"):
        checked_path("line.csv", line, "closed")  # ... a straight loop is not
    with pytest.raises(InputError, match="7 distinct points"):
        checked_path("short.csv", arc(3.0, 7), "open")
    there = arc(2.0, 30)
    back = np.vstack([there, there[-2::-1]])  # out and back along the same arc
    for kind in ("auto", "open", "closed"):
        with pytest.raises(InputError, match="doubles back on itself"):
            checked_path("back.csv", back, kind)
    # A single sharp reversal (a T's stem) is not a path doubling back.
    stem = np.vstack([arc(1.0, 20), arc(1.0, 20)[-2:10:-1], [[0.0, 2.0], [0.0, 3.0]]])
    checked_path("t.csv", stem, "open")


def test_sub_arcs_are_read_at_equal_arc_length():
    """A circle sampled unevenly by crank angle: each sub-arc's points, wrapping past the end of
    the revolution or not, lie on it, equally spaced along it, from the sub-arc's start to its
    end (to the chords' sag between samples)."""
    import torch

    from linkd.design.stroke import _along, _arc_table

    t = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    angle = t + 0.5 * np.sin(t)  # the crank's samples crowd where the angle turns slowly
    paths = torch.tensor(np.stack([np.cos(angle), np.sin(angle)], -1)[None], dtype=torch.float32)
    begin, length = np.array([0.0, 200.5, 64.0]), np.array([128.0, 100.0, 256.0])
    points = _along(
        *_arc_table(paths),
        torch.tensor(begin[None], dtype=torch.float32),
        torch.tensor(length[None], dtype=torch.float32),
        torch.linspace(0, 1, 32),
    )
    points = points.numpy()[0].astype(complex)  # fmt: skip
    assert np.allclose(np.abs(points), 1, atol=5e-4)
    steps = np.angle(points[:, 1:] / points[:, :-1])
    assert np.allclose(steps, steps.mean(1, keepdims=True), rtol=1e-2, atol=1e-4)
    unrolled = np.append(angle, 2 * np.pi)  # the angle at index k, cyclic
    for k, (first, span) in enumerate(zip(begin, length)):
        ends = [np.interp(i % 256, np.arange(257), unrolled) for i in (first, first + span)]
        assert np.allclose(points[k, [0, -1]], np.exp(1j * np.array(ends)), atol=5e-4)


def test_a_short_sub_arc_far_from_the_origin_fits_exactly():
    """A tenth of the revolution of a path 50 units from the origin, where the crank's samples
    crowd (a short arc, far from the path's middle), turned, scaled and moved as the target
    (walked forwards, and mirrored: backwards and reflected), fits with no error and the
    similarity it was made with: the fit's sums keep their digits."""
    import torch

    from linkd.design.stroke import _at, _fit

    t = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    angle = t + 0.9 * np.sin(t)  # turns slowly round t = pi
    path = np.stack([40 + 8 * np.cos(angle) + np.cos(2 * t), -30 + 5 * np.sin(angle)], -1)
    paths = torch.tensor(path[None], dtype=torch.float32)
    begin, length = torch.tensor([[115.0]]), torch.tensor([[25.6]])
    fraction = torch.linspace(0, 1, 32)
    arc = _at(paths.double(), (begin + length * fraction)[..., None, :].double())[0, 0].numpy()
    gain = 2.5 * np.exp(0.7j)
    joints = torch.tensor([[[arc[0].real, arc[0].imag]]], dtype=torch.float32)  # near the arc
    for mirrored, walked in ((0, arc), (1, np.conj(arc[::-1]))):
        z = torch.tensor(gain * walked + (3 - 1j), dtype=torch.complex64)
        score, fitted, _ = _fit(paths, joints, z, begin, length, fraction, None)
        assert score[0, mirrored, 0] < 1e-3 < score[0, 1 - mirrored, 0]
        assert abs(complex(fitted[0, mirrored, 0]) - gain) < 1e-3 * abs(gain)


def test_crank_range_in_mechanism_json(tmp_path):
    mech = classic.crank_rocker().replace(crank_range=(1.0, 3.5))
    mech.save(tmp_path / "m.json")
    data = json.loads((tmp_path / "m.json").read_text())
    assert data["crank_range"] == [1.0, 3.5]
    assert Mechanism.load(tmp_path / "m.json").crank_range == (1.0, 3.5)
    # A mirrored mechanism traces the mirrored stroke at mirrored angles.
    mirror = Similarity(1.0, rotation(0.0, reflect=True))
    flipped = mech.transformed(mirror)
    a, b = flipped.crank_range
    assert a == pytest.approx(2 * np.pi - 3.5) and b - a == pytest.approx(2.5)
    stroke = end_effector_path(mech, np.linspace(1.0, 3.5, 50))[0]
    mirrored = end_effector_path(flipped, np.linspace(a, b, 50))[0]
    np.testing.assert_allclose(mirrored[::-1], mirror.apply(stroke), atol=1e-9)
    for bad in ([3.0, 2.0], [7.0, 8.0], [0.0, 7.0], ["a", 1], [1.0]):
        data["crank_range"] = bad
        (tmp_path / "bad.json").write_text(json.dumps(data))
        with pytest.raises(InputError, match="crank_range"):
            Mechanism.load(tmp_path / "bad.json")


def options(**changes) -> DesignOptions:
    # One round and no atlas: later rounds and the atlas have their own tests.
    settings = dict(candidates=12, time_budget=600, refine_settings=QUICK, formats={"mjcf"},
                    every_joint=False, rounds=1, atlas=False)  # fmt: skip
    return DesignOptions(**{**settings, **changes})


def stroke_file(pool, folder, start: float, end: float, rows: int, name: str):
    """The pool's first mechanism's end effector at `rows` equal crank steps from `start` to
    `end` (radians), in the user's frame, as a curve CSV."""
    mech = from_graph(pool[0])
    path = end_effector_path(mech, np.linspace(start, end, rows))[0]
    file = folder / name
    write_curve(file, USER.apply(path))
    return file


def test_a_known_partial_stroke_is_recovered_with_its_range(pool, tmp_path):
    file = stroke_file(pool, tmp_path, 1.0, 3.5, 80, "stroke.csv")
    out = tmp_path / "stroke-design"
    opts = options(timed=True)
    outcome = design(file, out, opts, proposer=pool_proposer(pool), show=False)
    assert outcome.design is not None
    report = json.loads((out / "report.json").read_text())
    assert report["curve"]["path"] == "open" and report["verification"]["passed"]
    figures = report["design"]
    a, b = np.radians(figures["crank_range_deg"])
    # The same mechanism, possibly mirrored (a mirrored one runs the range backwards).
    assert (a, b) == pytest.approx((1.0, 3.5), abs=0.03) or b - a == pytest.approx(2.5, abs=0.03)
    assert figures["timing_error"] < 0.005 and figures["chamfer"] < 0.01
    mech = Mechanism.load(out / "mechanism.json")
    assert mech.crank_range == pytest.approx((a, b))


def test_a_motor_point_on_a_stroke_pins_the_pivot_there(pool, tmp_path):
    """A stroke's designs are pinned as a closed loop's are: placed about the motor point,
    refined with the pivot held, delivered with it exactly there."""
    file = stroke_file(pool, tmp_path, 1.0, 3.5, 80, "stroke.csv")
    motor = tuple(USER.apply(from_graph(pool[0]).positions[:1])[0])
    opts = options(timed=True, constraints=Constraints(motor_at=motor))
    outcome = design(file, tmp_path / "pinned", opts, proposer=pool_proposer(pool), show=False)
    assert outcome.design is not None
    mech = Mechanism.load(tmp_path / "pinned" / "mechanism.json")
    assert tuple(mech.positions[mech.motor[0]]) == motor  # exactly
    assert outcome.report["design"]["timing_error"] < 0.005


def test_timing_of_a_known_closed_path_is_recovered(pool, tmp_path):
    rows = 90
    phase = 0.8  # the rows start at this crank angle
    file = stroke_file(pool, tmp_path, phase, phase + 2 * np.pi * (rows - 1) / rows, rows,
                       "loop.csv")  # fmt: skip
    outcome = design(file, tmp_path / "timed", options(timed=True), proposer=pool_proposer(pool),
                     show=False)  # fmt: skip
    report = outcome.report
    assert report["curve"]["path"] == "closed" and report["curve"]["timed"]
    assert report["design"]["timing_error"] < 0.005
    assert "crank_range_deg" not in report["design"]
    # The timing error sees the timing: the same loop at equal arc-length steps is far off.
    points = np.loadtxt(file, delimiter=",", skiprows=1)
    uneven = timing_of(outcome.design.mechanism, resample(points, rows))
    assert uneven > 10 * report["design"]["timing_error"]


def test_a_stroke_is_searched_around_in_later_rounds(pool, tmp_path):
    """Later rounds grow a stroke's best designs as they grow a loop's, each copy placed on the
    stroke by its own best sub-arc, and refine the best of them."""
    file = stroke_file(pool, tmp_path, 2.0, 4.0, 60, "s.csv")
    outcome = design(file, tmp_path / "grown", options(rounds=2), proposer=pool_proposer(pool),
                     show=False)  # fmt: skip
    search = outcome.report["search"]
    assert search["rounds_run"] == 2 and outcome.design is not None
    grown = search["sources"]["round 2"]
    assert grown["placed"] > 0 and grown["refined"] > 0


def test_bench_reports_open_strokes(pool, tmp_path):
    file = stroke_file(pool, tmp_path, 2.0, 4.0, 60, "s.csv")
    lines = []
    results = run_bench([file], options(), pool_proposer(pool), say=lines.append, kinds=["open"])
    (row,) = results["curves"]
    assert row["path"] == "open" and row["verified"] and row["deviation"] < 0.02
    assert "deviation" in lines[0] and results["total"]["open"] == 1


@pytest.mark.parametrize(
    "rows, args, message",
    [
        (arc(3.0, 7), ["--path", "open"], "7 distinct points"),
        (np.vstack([arc(2.0, 30), arc(2.0, 30)[-2::-1]]), [], "doubles back"),
        (arc(3.0, 40), ["--path", "sideways"], "--path"),
    ],
)
def test_bad_open_input_exits_2_and_writes_nothing(tmp_path, monkeypatch, capsys, rows, args,
                                                   message):  # fmt: skip
    monkeypatch.chdir(tmp_path)
    write_curve("bad.csv", rows)
    assert main(["design", "bad.csv", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


def test_outputs_mark_the_working_stroke(tmp_path):
    from linkd.verify import write_curve_plot
    from linkd.verify.animation import scene_commands

    mech = classic.crank_rocker().replace(crank_range=(1.0, 3.5))
    target = end_effector_path(mech, np.linspace(1.0, 3.5, 40))[0]
    write_curve_plot(mech, tmp_path / "curve.png", target=target)
    assert (tmp_path / "curve.png").stat().st_size > 0
    commands = {c.get("path"): c for c in scene_commands(mech, target)}
    stroke = commands["/meshcat/linkd/working_stroke"]["object"]["object"]
    assert stroke["type"] == "Line"  # open, unlike the traced revolution
    assert commands["/meshcat/linkd/target"]["object"]["object"]["type"] == "Line"
    closed = {c.get("path"): c for c in scene_commands(classic.crank_rocker(), target)}
    assert "/meshcat/linkd/working_stroke" not in closed
