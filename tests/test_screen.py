"""A target curve of a million points is drawn at screen resolution: the page stays small and
the drawn line stays within a pixel of every point of the user's curve."""

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from linkd.classic import crank_rocker
from linkd.curves import resample
from linkd.verify.analytic import joint_paths
from linkd.verify.animation import scene_commands, write_animation
from linkd.verify.screen import MAX_POINTS, PIXELS, screen_polyline


def _star(n: int) -> np.ndarray:
    """A closed star with sharp tips, sampled unevenly (dense on one side)."""
    u = np.linspace(0, 2 * np.pi, 11)
    corners = np.c_[np.cos(u), np.sin(u)] * np.where(np.arange(11) % 2, 0.4, 1.0)[:, None]
    t = np.linspace(0, 1, n, endpoint=False) ** 1.5 * 10
    k = t.astype(int)
    return 50 * (corners[k] + (t - k)[:, None] * (corners[k + 1] - corners[k])) + [300, -20]


def _within(drawn: np.ndarray, points: np.ndarray) -> float:
    """The largest distance from a point of `points` to the nearest vertex of `drawn`."""
    return float(cKDTree(drawn).query(points)[0].max())


def test_thinned_polyline_stays_within_a_pixel_of_every_point():
    points = _star(300_000)
    drawn = screen_polyline(points)
    cell = np.ptp(points, axis=0).max() / PIXELS
    assert len(drawn) < 30_000
    assert _within(drawn, points) <= np.sqrt(2) * cell
    np.testing.assert_array_equal(drawn[[0, -1]], points[[0, -1]])  # both ends kept
    few = _star(200)
    np.testing.assert_array_equal(screen_polyline(few), few)  # already coarser than pixels


def test_noise_is_thinned_to_a_bounded_number_of_points():
    noise = np.random.default_rng(0).normal(size=(1_000_000, 2))
    assert len(screen_polyline(noise)) == MAX_POINTS


def test_a_million_point_target_gives_a_small_page(tmp_path: Path):
    mech = crank_rocker()
    target = resample(joint_paths(mech, 400)[mech.end_effector], 1_000_000) * 1.02
    (line,) = [c for c in scene_commands(mech, target) if c["path"].endswith("/target")]
    data = line["object"]["geometries"][0]["data"]["attributes"]["position"]["array"].data
    drawn = np.frombuffer(data, dtype=np.float32).reshape(-1, 3)[:, :2]
    assert len(drawn) < 20_000
    assert _within(drawn, target[::7]) <= 2 * np.ptp(target, axis=0).max() / PIXELS
    write_animation(mech, tmp_path / "animation.html", target=target)
    assert (tmp_path / "animation.html").stat().st_size < 2_000_000  # was 17 MB
