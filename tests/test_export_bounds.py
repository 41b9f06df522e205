"""Bounds of a refused mechanism (linkd.export.bounds): nothing to hold otherwise where the
export builds it, the pivots that keep a refused one from layering, brackets and rings there;
`linkd bench export --bounds` prints them for each refusal."""

import linkd.verified
from linkd.classic import crank_rocker
from linkd.cli import main
from linkd.export.bounds import bounds
from linkd.export.layers import NoFlatLayers
from linkd.mechanism import Mechanism

# Generated (seed 8, no. 198 of 200, 5 to 20 joints), in mm; refused by the export.
REFUSED = Mechanism(
    [(-74.394, 10.59), (-99.085, 46.229), (-92.323, -55.534), (-66.278, -88.697), (72.47, 77.526),
     (-24.24, -73.006), (-69.065, 7.03), (23.673, -73.958), (-20.084, -96.594), (18.019, 36.726),
     (-41.49, 78.8), (-11.693, -24.098), (75.138, 54.863), (-50.683, 22.564), (-13.401, -44.814),
     (-36.607, 11.46), (14.177, -88.128), (-56.171, -53.488)],
    [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 0, 0, 0, 0, 1, 0, 0],
    [(0, 1), (0, 2), (0, 3), (0, 12), (1, 2), (1, 5), (1, 9), (1, 17), (2, 3), (2, 7), (2, 16),
     (4, 5), (4, 6), (4, 13), (5, 6), (6, 7), (6, 13), (6, 17), (7, 12), (8, 9), (9, 11), (9, 14),
     (10, 11), (10, 14), (15, 16)],
    (0, 1), 17, units="mm",
)  # fmt: skip


def test_a_mechanism_the_export_builds_needs_nothing_held_otherwise():
    found = bounds(crank_rocker())
    assert found.held == ((),) and not found.brackets and not found.rings
    assert found.describe() == "layers with every ground pin as a pin or stubs"


def test_a_refused_mechanism_needs_a_pivot_held_otherwise_and_no_bracket_does():
    found = bounds(REFUSED)
    assert found.held == ((0,), (15,))  # the motor's pivot, or pivot 15, and no pin there
    assert all(ok == 0 and tried == total > 0 for ok, tried, total in found.brackets.values())
    assert found.rings[(0,)] == ((0, 5),)  # the motor's pivot on a ring: no split layers
    (ok, splits), (barred, directions) = found.rings[(15,)]
    assert 0 < ok < splits  # a ring at 15 would, if nothing held it,
    assert barred == 0 and directions == 16  # but with a bar in any direction, none
    assert found.describe().startswith("layers only with pivots 0 or 15 held otherwise")


def test_bench_export_prints_the_bounds_of_each_refusal(monkeypatch, capsys):
    real = linkd.verified.export_verified

    def refuse_the_first(mech, *args, **kwargs):  # a refusal planted on the run's no. 0
        if refuse_the_first.calls == 0:
            refuse_the_first.calls += 1
            raise NoFlatLayers("planted")
        return real(mech, *args, **kwargs)

    refuse_the_first.calls = 0
    monkeypatch.setattr(linkd.verified, "export_verified", refuse_the_first)
    assert main(["bench", "export", "--count", "2", "--seed", "5", "--max-joints", "7",
                 "--bounds"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "the refused ones             no. 0" in out
    assert "bounds (0.25 of the width)    no. 0: layers with every ground pin" in out
