"""curve.png: a PNG of the target, the traced path and the mechanism, written atomically."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from linkd.classic import jansen_leg, non_grashof_four_bar
from linkd.verify.analytic import joint_paths
from linkd.verify.plot import write_curve_plot


def test_curve_plot_is_a_drawn_png(tmp_path: Path) -> None:
    from PIL import Image

    mech = jansen_leg()
    path = tmp_path / "curve.png"
    write_curve_plot(mech, path, target=joint_paths(mech, 40)[mech.end_effector] * 1.05)
    image = np.asarray(Image.open(path).convert("RGB"))
    assert image.shape[0] >= 400 and image.shape[1] >= 400
    red = (image[..., 0] > 180) & (image[..., 1] < 80) & (image[..., 2] < 80)
    blue = (image[..., 2] > 150) & (image[..., 0] < 150)
    assert red.sum() > 100 and blue.sum() > 100  # the traced path and the target are drawn
    assert [p.name for p in tmp_path.iterdir()] == ["curve.png"]  # no temporary left behind
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask  # like any other output


def test_curve_plot_of_a_locking_mechanism_writes_nothing(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="locks"):
        write_curve_plot(non_grashof_four_bar(), tmp_path / "curve.png")
    assert not any(tmp_path.iterdir())
