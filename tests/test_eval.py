"""Evaluation: Chamfer of designs, curve sources, the report files and the command line."""

import json

import numpy as np
import pytest
import torch

from linkd.cli import main
from linkd.curves import write_curve
from linkd.evaluate import (
    BASELINE,
    Targets,
    conditioning_gap,
    design_chamfer,
    evaluate,
    folder_targets,
    node_counts,
    table,
    write_report,
)
from linkd.generator import generate
from linkd.model import LinkD, LinkDConfig, save_checkpoint

TINY = LinkDConfig(dim=32, layers=1, heads=2, encoder_layers=1, head_widths=(32, 16), head_cond=16)


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def samples():
    return generate(8, 21)


def test_a_mechanism_scores_zero_against_its_own_curve(samples):
    distance = design_chamfer(samples.graphs, samples.curves)
    assert np.all(distance < 1e-4)
    other = design_chamfer(samples.graphs, np.roll(samples.curves, 1, axis=0))
    assert np.all(other > 0.05)


def test_invalid_designs_have_no_distance(samples):
    broken = samples.graphs.copy()
    broken[0, 3, 4:] = np.where(np.arange(20) < 3, 1, broken[0, 3, 4:])  # three links
    distance = design_chamfer(broken, samples.curves)
    assert np.isnan(distance[0]) and np.isfinite(distance[1:]).all()
    np.testing.assert_array_equal(node_counts(samples.graphs), samples.n_nodes)


def test_folder_targets_read_resample_and_normalise(tmp_path):
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    write_curve(tmp_path / "b.csv", np.stack([10 + 3 * np.cos(t), 5 * np.sin(t)], 1))
    write_curve(tmp_path / "a.csv", np.stack([np.cos(t), np.sin(2 * t) + 2 * np.sin(t)], 1))
    targets = folder_targets(tmp_path)
    assert targets.name == tmp_path.name
    assert targets.conditioning.shape == (2, 200, 2) and targets.targets.shape == (2, 200, 2)
    np.testing.assert_allclose(targets.conditioning.mean(1), 0, atol=0.02)
    # sorted by file name: a.csv (the figure of eight) first; its x-range is the smaller one
    spread = np.ptp(targets.conditioning, axis=1)
    assert spread[0, 0] < spread[0, 1] and spread[1, 0] < spread[1, 1]


def test_evaluation_reports_every_strategy_and_seed(samples, tmp_path):
    torch.manual_seed(0)
    model = LinkD(TINY).eval()
    targets = Targets("gen", samples.curves[:3], samples.curves[:3])
    results = evaluate(model, targets, ("oneshot", "node"), seeds=(0, 1), retries=2)
    for name in ("oneshot", "node"):
        s = results["strategies"][name]
        assert [r["seed"] for r in s["runs"]] == [0, 1]
        assert all(len(r["node_counts"]) == 3 for r in s["runs"])
        assert s["success_mean"] == pytest.approx(np.mean([r["success"] for r in s["runs"]]))
    write_report(results, tmp_path / "report")
    for name in ("results.json", "table.txt", "strategies.png", "node_counts.png"):
        assert (tmp_path / "report" / name).stat().st_size > 0
    assert json.loads((tmp_path / "report" / "results.json").read_text())["curves"] == 3
    assert "oneshot" in table(results) and "node" in table(results)


def test_eval_command(samples, tmp_path, capsys):
    torch.manual_seed(0)
    save_checkpoint(tmp_path / "m.pt", LinkD(TINY))
    curves = tmp_path / "curves"
    curves.mkdir()
    for k in range(2):
        write_curve(curves / f"{k}.csv", samples.curves[k])
    args = ["eval", str(curves), "--checkpoint", str(tmp_path / "m.pt"), "--seeds", "2",
            "--strategies", "oneshot", "--speed", "0", "--out", str(tmp_path / "out")]  # fmt: skip
    assert main(args) == 0
    assert "oneshot" in capsys.readouterr().out
    assert (tmp_path / "out" / "curves" / "results.json").exists()
    assert main([*args[:-2], "--strategies", "beam"]) == 2
    assert main(["eval", str(tmp_path / "nowhere")]) == 2


def test_the_curve_blind_baseline_is_scored_like_a_strategy(samples):
    model = LinkD(TINY).eval()
    targets = Targets("gen", samples.curves[:4], samples.curves[:4])
    results = evaluate(model, targets, (BASELINE,), seeds=(0, 1))
    runs = results["strategies"][BASELINE]["runs"]
    assert all(r["success"] == 1.0 for r in runs)  # the generator's mechanisms are valid
    assert runs[0]["node_counts"] != runs[1]["node_counts"]  # a new draw per seed
    assert all(r["chamfer"] > 0.05 for r in runs)  # blind to the curve, so it misses it


def test_conditioning_gap_is_zero_for_a_model_that_ignores_the_curve(samples):
    torch.manual_seed(0)
    graphs, curves = torch.as_tensor(samples.graphs), torch.as_tensor(samples.curves)
    blind = LinkD(TINY)  # adaLN starts at zero and no cross-attention: the curve is unused
    with torch.no_grad():
        blind.backbone.final[1].weight.zero_()  # ... but for the final modulation
    gap = conditioning_gap(blind, graphs, curves)
    assert gap["gap"]["loss"] == pytest.approx(0.0, abs=1e-6)
    assert gap["own"]["loss"] > 0 and set(gap["gap"]) == set(gap["own"])
    seeing = LinkD(TINY)
    with torch.no_grad():
        for p in seeing.parameters():
            p.add_(0.1 * torch.randn_like(p))
    assert abs(conditioning_gap(seeing, graphs, curves)["gap"]["loss"]) > 1e-4
