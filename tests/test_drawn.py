"""Reading messy drawn input: uneven spacing, repeated points, jitter and crossings give the
target the author meant."""

import numpy as np

from linkd.curves import chamfer, resample
from linkd.design.drawn import read_target


def _figure_eight(t: np.ndarray) -> np.ndarray:
    return np.stack([np.sin(t), np.sin(t) * np.cos(t)], -1)


def _clean(n: int = 200) -> np.ndarray:
    return resample(_figure_eight(np.linspace(0, 2 * np.pi, 4000, endpoint=False)), n)


def test_uneven_spacing_and_repeated_points_do_not_matter():
    t = np.linspace(0, 1, 300, endpoint=False) ** 2 * 2 * np.pi  # crowded at the start
    drawn = np.repeat(_figure_eight(t), np.arange(300) % 4 + 1, axis=0)  # pauses
    target = read_target(drawn, 200)
    spacing = np.linalg.norm(np.diff(np.vstack([target, target[:1]]), axis=0), axis=1)
    assert spacing.max() < 1.05 * spacing.min()
    assert chamfer(target, _clean()) < 0.01


def test_a_self_crossing_keeps_the_order_drawn():
    target = read_target(_figure_eight(np.linspace(0, 2 * np.pi, 500, endpoint=False)), 200)
    # The crossing at the origin is passed twice, half a curve apart, in the order drawn.
    near = np.flatnonzero(np.linalg.norm(target, axis=1) < 0.02)
    assert len(near) >= 2 and np.ptp(near) > 80
    assert chamfer(target, _clean()) < 0.005


def test_jitter_is_averaged_and_smoothing_is_an_option():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 2 * np.pi, 5000, endpoint=False)
    shaky = _figure_eight(t) + rng.normal(0, 0.01, (5000, 2))
    picked = resample(shaky, 200)  # the plain resampling picks jitter up at random
    read = read_target(shaky, 200)
    smoothed = read_target(shaky, 200, smooth=0.003)
    clean = _clean()
    assert chamfer(read, clean) < 0.6 * chamfer(picked, clean)
    assert chamfer(smoothed, clean) < chamfer(read, clean)


def test_a_clean_curve_is_read_as_it_is():
    clean = _clean()
    assert chamfer(read_target(clean, 200), clean) < 0.002


def test_bad_search_options_exit_2_and_write_nothing(tmp_path, monkeypatch, capsys):
    from linkd.cli import main

    monkeypatch.chdir(tmp_path)
    curve = tmp_path / "c.csv"
    curve.write_text("\n".join(f"{x},{y}" for x, y in _clean(40)))
    for option in (["--smooth", "2"], ["--rounds", "0"], ["--atlas", "missing.npz"]):
        assert main(["design", str(curve), *option]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert [p.name for p in tmp_path.iterdir()] == ["c.csv"]
