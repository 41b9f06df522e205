"""Export with verification: a model whose loops are too soft at the default time step gets a
finer one, written in mechanism.xml; a model that passes keeps the default and the same file."""

from __future__ import annotations

import mujoco
import numpy as np

from linkd import classic
from linkd.classic import place
from linkd.cli import main
from linkd.export import TIMESTEP, export_mechanism, set_timestep
from linkd.geometry import Similarity
from linkd.mechanism import Mechanism
from linkd.verified import FINEST, export_verified
from linkd.verify import verify_output
from linkd.verify.checks import DYNAMIC_PATH_RTOL


def near_toggle_four_bar(margin: float = 5e-5) -> Mechanism:
    """Crank 1, coupler 3 + margin, rocker 2, ground 4 (x 25 mm): crank + ground exceed
    coupler + rocker by the margin, so the coupler and rocker almost fold flat once a turn. At
    0.25 ms and a margin of 5e-5 its end effector leaves the analytic path by about 8 times the
    dynamics check's tolerance."""
    o, g = np.array([0.0, 0.0]), np.array([4.0, 0.0])
    m = np.array([0.0, 1.0])
    c = place(m, g, 3.0 + margin, 2.0, -1)
    p = place(m, c, 2.1, 1.8, 1)
    links = [(0, 1), (1, 3), (2, 3), (1, 4), (3, 4)]
    return Mechanism(np.array([o, m, g, c, p]) * 25, [1, 0, 1, 0, 0], links, (0, 1), 4)


def test_soft_loops_get_a_finer_step_that_verify_checks(tmp_path):
    _, report = export_verified(near_toggle_four_bar(), tmp_path, {"mjcf", "stl"})
    step = report.check("dynamics").figures["timestep_s"]
    assert report.passed and step < TIMESTEP
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "mechanism.xml"))
    assert model.opt.timestep == step and model.eq_solref[0, 0] == 2 * step
    assert main(["verify", str(tmp_path)]) == 0  # the folder as written, unchanged tolerances
    set_timestep(tmp_path, TIMESTEP)  # the same model at the default step misses them
    default = verify_output(tmp_path, write=False)
    assert default.failed == ["dynamics"]
    assert default.check("dynamics").figures["path_error"] > 4 * DYNAMIC_PATH_RTOL


def test_a_model_that_passes_keeps_the_default_step_and_file(tmp_path):
    mech = classic.crank_rocker().transformed(Similarity(25.0))
    verified, plain = tmp_path / "verified", tmp_path / "plain"
    verified.mkdir(), plain.mkdir()
    _, report = export_verified(mech, verified, {"mjcf"})
    export_mechanism(mech, plain, {"mjcf"})
    assert report.passed and report.check("dynamics").figures["timestep_s"] == TIMESTEP
    assert (verified / "mechanism.xml").read_text() == (plain / "mechanism.xml").read_text()
    set_timestep(plain, TIMESTEP / 2)  # rewriting the step changes only the step
    assert (verified / "mechanism.xml").read_text() != (plain / "mechanism.xml").read_text()
    set_timestep(plain, TIMESTEP)
    assert (verified / "mechanism.xml").read_text() == (plain / "mechanism.xml").read_text()


def test_a_model_no_step_can_save_is_not_run_again(tmp_path):
    said: list[str] = []
    mech = near_toggle_four_bar(5e-6)
    _, report = export_verified(mech, tmp_path, {"mjcf"}, progress=said.append)
    assert report.failed == ["dynamics"]
    assert report.check("dynamics").figures["timestep_s"] == TIMESTEP
    assert not any("again" in text for text in said)
    set_timestep(tmp_path, FINEST)  # and indeed the finest step would not have saved it
    assert verify_output(tmp_path, write=False).failed == ["dynamics"]
