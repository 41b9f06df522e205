"""`linkd bench design`: which curves it runs on and the figures it reports."""

import numpy as np
import pytest

from linkd.curves import resample, write_curve
from linkd.design.bench import curve_files, run_bench, summary_table
from linkd.design.pipeline import DesignOptions
from linkd.design.select import curve_error, end_effector_path, sampling_floor
from linkd.errors import InputError
from linkd.generator import GeneratorSettings, generate
from linkd.graph import from_graph


def test_curve_files_takes_files_and_folders(tmp_path):
    folder = tmp_path / "set"
    folder.mkdir()
    for name in ("b.csv", "a.csv", "index.csv", "notes.txt"):
        (folder / name).write_text("x,y\n")
    single = tmp_path / "z.csv"
    single.write_text("x,y\n")
    assert [p.name for p in curve_files([str(folder), str(single)])] == ["a.csv", "b.csv", "z.csv"]
    assert len(curve_files([str(folder)], limit=1)) == 1
    with pytest.raises(InputError):
        curve_files([str(tmp_path / "missing")])


def test_bench_reports_validity_error_and_time_per_curve(tmp_path):
    settings = GeneratorSettings(min_nodes=5, max_nodes=6)
    graphs = generate(6, seed=11, settings=settings).graphs
    files = []
    for k in range(2):
        path = end_effector_path(from_graph(graphs[k]), 600)[0]
        files.append(tmp_path / f"{k}.csv")
        write_curve(files[-1], 25.0 * resample(path, 120))

    def proposer(curves, per_curve, seed):
        return graphs[np.resize(np.arange(len(graphs)), len(curves) * per_curve)]

    lines = []
    options = DesignOptions(candidates=6, refine=False, formats=frozenset({"mjcf"}), atlas=False)
    results = run_bench(files, options, proposer, say=lines.append)
    assert len(results["curves"]) == 2 and len(lines) == 2
    total = results["total"]
    assert total["valid_rate"] == 1.0 and total["verified_rate"] == 1.0
    for row in results["curves"]:
        assert 0 <= row["chamfer"] < 1 and 0 <= row["chamfer_200"] < 1
        assert 5 <= row["nodes"] <= 6 and row["seconds"] > 0
    assert "verified        100.0%" in summary_table(total)
    assert all(0 < row["floor"] < row["chamfer"] for row in results["curves"])
    assert total["floor_mean"] == pytest.approx(np.mean([r["floor"] for r in results["curves"]]))
    assert total["found_by"] == {"model": 2}  # the only source here
    skips = sum(sum(row["skipped"].values()) for row in results["curves"])
    assert sum(total["skipped"].values()) == skips and total["best_skipped"] <= min(skips, 2)
    assert "best designs passed over" in summary_table(total)
    assert total["stages"]["model, placed"] >= total["stages"]["+ atlas, placed"]
    # the median of each stage's seconds, over the curves' own timings
    assert set(total["stage_seconds"]) >= {"propose", "align", "verify"}
    proposing = [row["timings"]["propose_s"] for row in results["curves"]]
    assert total["stage_seconds"]["propose"] == pytest.approx(np.median(proposing))
    line = next(x for x in summary_table(total).splitlines() if x.startswith("stage seconds"))
    assert f"propose {total['stage_seconds']['propose']:.1f}" in line


def test_bench_counts_a_refused_curve_and_goes_on(tmp_path):
    """A curve linkd refuses (here far too small) is a row without a design, not the end of
    the benchmark."""
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    tiny, bad = tmp_path / "tiny.csv", tmp_path / "bad.csv"
    write_curve(tiny, 1e-6 * np.c_[np.cos(t), np.sin(t)])
    bad.write_text("x,y\n1,2\n")
    lines = []
    results = run_bench([tiny, bad], DesignOptions(atlas=False), None, say=lines.append)
    assert [row["valid"] for row in results["curves"]] == [False, False] and len(lines) == 2
    assert "across" in results["curves"][0]["reason"] and "across" in lines[0]
    assert results["total"]["valid_rate"] == 0.0 and results["total"]["chamfer_mean"] is None


def test_the_sampling_floor_is_what_an_exact_trace_scores():
    """Both curves resampled to 2000 points from their own starts: a circle traced exactly but
    from elsewhere scores a quarter of the spacing each way on average, half in all."""
    turn = np.linspace(0, 2 * np.pi, 500, endpoint=False)
    circle = np.stack([np.cos(turn), np.sin(turn)], 1)
    assert sampling_floor(circle) == pytest.approx(0.5 * 2 * np.pi / 2000, rel=0.1)
    assert curve_error(circle, circle) == pytest.approx(0, abs=1e-12)  # from its own start
    assert sampling_floor(3 * circle + 7) == pytest.approx(sampling_floor(circle), rel=1e-6)
