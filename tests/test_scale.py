"""Scale extremes: curves and mechanisms too small or too large to build are refused up front
with one line naming the size and the range (exit 2, nothing written, no traceback)."""

import numpy as np
import pytest

from linkd import classic
from linkd.cli import main
from linkd.errors import InputError
from linkd.export import export_mechanism
from linkd.geometry import Similarity, rotation
from linkd.scale import check_curve_size


def _ellipse(path, size):
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    np.savetxt(path, np.c_[size / 2 * np.cos(t), size / 4 * np.sin(t)], delimiter=",")


@pytest.mark.parametrize("size", [1e12, 1e-12])
def test_design_refuses_a_curve_outside_the_buildable_range(tmp_path, capsys, size):
    curve, out = tmp_path / "curve.csv", tmp_path / "out"
    _ellipse(curve, size)
    assert main(["design", str(curve), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "curve.csv" in err[0]
    assert f"{size:.3g} mm across" in err[0] and "from 0.05 mm to 100 m" in err[0]
    assert not out.exists()


def test_design_range_is_in_the_curves_units(tmp_path, capsys):
    """500 units across is fine in millimetres, refused in metres (above 100 m)."""
    curve = tmp_path / "curve.csv"
    _ellipse(curve, 500.0)
    assert main(["design", str(curve), "--units", "m", "--out", str(tmp_path / "o")]) == 2
    assert "500 m across" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("scale", [1e12, 1e-9])
def test_export_refuses_a_mechanism_outside_the_buildable_range(tmp_path, capsys, scale):
    mech = classic.crank_rocker().transformed(Similarity(scale))
    path, out = tmp_path / "m.json", tmp_path / "out"
    mech.save(path)
    assert main(["export", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "from 0.1 mm to 1 km across" in err[0]
    assert not out.exists()
    with pytest.raises(ValueError, match="mechanism is"):
        export_mechanism(mech, tmp_path)
    assert not (tmp_path / "mechanism.json").exists()


def test_a_small_drawn_curve_is_within_range():
    """LInK-Bench's gcp/07 is 0.43 mm across: small, but its designs export and verify."""
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    check_curve_size(np.c_[0.43 / 2 * np.cos(t), 0.1 * np.sin(t)], "mm", "curve.csv")
    with pytest.raises(InputError, match=r"from 0\.05 mm to 100 m"):
        check_curve_size(np.c_[0.04 / 2 * np.cos(t), 0.01 * np.sin(t)], "mm", "curve.csv")


def test_a_tenth_of_a_millimetre_mechanism_exports_and_verifies(tmp_path):
    """0.12 mm across: the parts' gaps are microns, about MuJoCo's own distance tolerance for
    meshes, which then finds contacts between parts that do not touch; the model's tolerance
    follows its gaps, so every check of `linkd verify` passes."""
    from linkd.verified import export_verified

    mech = classic.crank_rocker().transformed(Similarity(0.03))
    _, report = export_verified(mech, tmp_path, {"mjcf", "stl"})
    assert report.passed, report.failed


def test_a_millimetre_sized_model_weighs_its_parts_in_proportion(tmp_path):
    """MuJoCo floors every body's mass and inertia (1e-9 kg, 1e-14 kg m^2): the parts of a
    0.4 mm mechanism weigh less, so at its true density they would all weigh the same and turn
    like flywheels. Its density is raised instead, so its bodies' masses keep the proportions
    of the same mechanism built a metre across (inertias those times the square of the scale)."""
    import mujoco

    def bodies(mech, out):
        result = export_mechanism(mech, out, {"mjcf", "stl"})
        model = mujoco.MjModel.from_xml_path(str(out / "mechanism.xml"))
        moving = model.body_dofnum > 0
        density = result.sizes["density"]
        return model.body_mass[moving] / density, model.body_inertia[moving] / density, density

    big = classic.crank_rocker().transformed(Similarity(100.0))  # 0.4 m across
    tiny = classic.crank_rocker().transformed(Similarity(0.1))
    (tmp_path / "big").mkdir()
    (tmp_path / "tiny").mkdir()
    mass, inertia, density = bodies(big, tmp_path / "big")
    tiny_mass, tiny_inertia, tiny_density = bodies(tiny, tmp_path / "tiny")
    assert density == 1200 and tiny_density > 1200
    np.testing.assert_allclose(tiny_mass / mass, 1e-9, rtol=1e-3)
    np.testing.assert_allclose(tiny_inertia / inertia, 1e-15, rtol=1e-3)


@pytest.mark.parametrize("offset", [1e7, 1e9])  # 10 km and 1000 km, in mm
def test_a_mechanism_far_from_the_origin_exports_and_verifies(tmp_path, offset):
    """In the user's frame, far from its origin: the ground's meshes are written about the motor
    pivot (MuJoCo keeps meshes in single precision), the MJCF's numbers read back exactly (at
    twelve figures a motor pivot 1000 km out moved by microns), the validator compares joints
    about their centroid and the pose solver asks only what rounding there allows. Turned by a
    radian and moved by pi / 3 times the offset, so that no coordinate is round."""
    from linkd.validator import validate_mechanism
    from linkd.verified import export_verified

    move = np.array([offset, -offset]) * np.pi / 3
    mech = classic.crank_rocker().transformed(Similarity(100.0, rotation(1.0), move))
    assert validate_mechanism(mech)[0] == 0
    _, report = export_verified(mech, tmp_path, {"mjcf", "stl"})
    assert report.passed, report.failed


def test_a_size_is_stated_once_to_three_figures(tmp_path, capsys):
    """A tiny mechanism in millimetres is named once (its size in words would say the same), a
    huge one once more in kilometres, both to three figures."""
    cases = [(1.234e-10, "4.94e-10 mm across;"), (1.234e10, "4.94e+10 mm across (4.94e+04 km);")]
    for scale, said in cases:
        path = tmp_path / "m.json"
        classic.crank_rocker().transformed(Similarity(scale)).save(path)
        assert main(["export", str(path), "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert said in err and "4.936" not in err


def test_a_mechanism_too_far_from_the_origin_is_refused(tmp_path, capsys):
    """1e12 mm out, about 3e9 times its size: rounding there would move its joints by more than
    verification allows, so it is refused up front, as the curve of a design is."""
    mech = classic.crank_rocker().transformed(Similarity(100.0, translation=np.array([1e12, 0])))
    path, out = tmp_path / "m.json", tmp_path / "out"
    mech.save(path)
    assert main(["export", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "lies 1e+12 mm from the origin" in err[0] and "1e+07 times" in err[0]
    assert not out.exists()
    curve = tmp_path / "curve.csv"
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    np.savetxt(curve, np.c_[1e10 + 50 * np.cos(t), 25 * np.sin(t)], delimiter=",")
    assert main(["design", str(curve), "--out", str(out)]) == 2
    assert "curve lies 1e+10 mm from the origin" in capsys.readouterr().err
    assert not out.exists()
