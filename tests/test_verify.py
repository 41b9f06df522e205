"""`linkd verify`: pose solving, passing verdicts on real exports, and planted defects caught.

Real exports come from `linkd.export.export_mechanism`; the defects are planted in their files
(all plates on one layer, a loop closure removed, the design file moved off the model). A
four-bar written by hand here, outside the exporter, checks the checks on an independent model
and gives the mechanism that cannot turn fully (a non-Grashof four-bar).
"""

from __future__ import annotations

import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest

from linkd.classic import crank_rocker, non_grashof_four_bar
from linkd.cli import main
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.mechanism import UNITS_IN_METRES, Mechanism
from linkd.verify.analytic import joint_paths
from linkd.verify.collisions import box_distances, check_collisions, classify_pairs
from linkd.verify.pose import solve_pose, solve_sweep
from linkd.verify.runner import verify_output

EXAMPLES = Path(__file__).parents[1] / "assets" / "examples"


def four_bar_xml(mech: Mechanism) -> str:
    """A hand-written MJCF of a four-bar O-M-C-G with coupler point P (classic joint order).

    Crank, coupler and rocker are capsules on three layers; the loop closes at C.
    """
    unit = UNITS_IN_METRES[mech.units]
    o, m, g, c, p = mech.positions * unit
    r, pitch = 0.02 * mech.scale * unit, 0.1 * mech.scale * unit

    def at(*points: np.ndarray, z: float) -> str:
        return " ".join(f"{v:.12g} {w:.12g} {z:.12g}" for v, w in points)

    return f"""<mujoco model="hand-built four-bar">
  <option timestep="5e-4" integrator="RK4" solver="Newton" tolerance="1e-12">
    <flag filterparent="disable"/>
  </option>
  <default>
    <joint type="hinge" axis="0 0 1"/>
    <geom type="capsule" size="{r:.12g}" density="1200"/>
    <equality solref="1e-3 1" solimp="0.9999 0.9999 0.001 0.5 2"/>
  </default>
  <worldbody>
    <body name="crank" pos="{at(o, z=0)}">
      <joint name="crank"/>
      <geom fromto="{at(0 * o, m - o, z=0)}"/>
      <body name="coupler" pos="{at(m - o, z=0)}">
        <joint name="coupler"/>
        <geom fromto="{at(0 * m, c - m, z=pitch)}"/>
        <geom fromto="{at(0 * m, p - m, z=pitch)}"/>
        <geom fromto="{at(c - m, p - m, z=pitch)}"/>
        <site name="coupler_at_c" pos="{at(c - m, z=0)}"/>
        <site name="end_effector" pos="{at(p - m, z=0)}"/>
      </body>
    </body>
    <body name="rocker" pos="{at(g, z=0)}">
      <joint name="rocker"/>
      <geom fromto="{at(0 * g, c - g, z=2 * pitch)}"/>
      <site name="rocker_at_c" pos="{at(c - g, z=0)}"/>
    </body>
  </worldbody>
  <equality><connect site1="coupler_at_c" site2="rocker_at_c"/></equality>
  <actuator><position name="motor" joint="crank" kp="4e-3" kv="1.2e-4"/></actuator>
</mujoco>
"""


def hand_built(folder: Path, mech: Mechanism) -> Path:
    folder.mkdir()
    mech.save(folder / "mechanism.json")
    (folder / "mechanism.xml").write_text(four_bar_xml(mech))
    return folder


def scaled(mech: Mechanism, factor: float = 25.0) -> Mechanism:
    """The classic four-bars measure a few units; make them a few centimetres (in mm)."""
    return mech.replace(positions=mech.positions * factor)


# ---- pose solving ------------------------------------------------------------------------------


def test_solve_sweep_follows_the_analytic_path(tmp_path: Path) -> None:
    mech = scaled(crank_rocker())
    model = mujoco.MjModel.from_xml_string(four_bar_xml(mech))
    data = mujoco.MjData(model)
    angles = np.linspace(0, 2 * np.pi, 90, endpoint=False)
    poses = solve_sweep(model, data, angles)
    site = model.site("end_effector").id
    expected = joint_paths(mech, angles)[mech.end_effector] * 1e-3
    found = []
    for qpos in poses:
        data.qpos[:] = qpos
        mujoco.mj_kinematics(model, data)
        found.append(data.site_xpos[site, :2].copy())
    radius = np.sqrt(((expected - expected.mean(0)) ** 2).sum(1).mean())
    assert np.abs(np.array(found) - expected).max() < 1e-9 * radius
    np.testing.assert_allclose(poses[:, 0], angles, atol=1e-12)  # the crank held as asked


def test_solve_pose_keeps_the_assembly_branch() -> None:
    mech = scaled(crank_rocker())
    model = mujoco.MjModel.from_xml_string(four_bar_xml(mech))
    data = mujoco.MjData(model)
    sweep = solve_sweep(model, data, np.array([0.4, 0.8]))
    single = solve_pose(model, data, 0.8, qpos0=sweep[0])
    np.testing.assert_allclose(single, sweep[1], atol=1e-10)
    with pytest.raises(ValueError, match="do not close"):
        locked = scaled(non_grashof_four_bar())
        model = mujoco.MjModel.from_xml_string(four_bar_xml(locked))
        solve_sweep(model, mujoco.MjData(model), np.linspace(0, 2 * np.pi, 60))


# ---- verdicts ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def jansen_export(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from linkd.export import export_mechanism

    out = tmp_path_factory.mktemp("jansen")
    export_mechanism(Mechanism.load(EXAMPLES / "jansen_leg.json"), out, {"mjcf", "stl"})
    return out


def planted(export: Path, tmp_path: Path) -> Path:
    """A copy of an export to plant a defect in."""
    folder = tmp_path / "out"
    shutil.copytree(export, folder)
    return folder


def edit_model(folder: Path, change) -> None:
    tree = ET.parse(folder / "mechanism.xml")
    change(tree.getroot())
    tree.write(folder / "mechanism.xml")


def test_jansen_export_passes_and_reports(jansen_export: Path, tmp_path: Path) -> None:
    folder = planted(jansen_export, tmp_path)
    (folder / "report.json").write_text(json.dumps({"curve_error": 0.5}))
    report = verify_output(folder)
    assert report.passed, [(c.name, c.detail) for c in report.checks]
    written = json.loads((folder / "report.json").read_text())
    assert written["curve_error"] == 0.5  # merged, not replaced
    checks = {c["name"]: c for c in written["verification"]["checks"]}
    assert list(checks) == ["load", "mobility", "kinematics", "dynamics", "collisions"]
    assert checks["kinematics"]["figure"] < 1e-6 and checks["collisions"]["figure"] > 0
    assert written["verification"]["thresholds"]["loop_rtol"] == 1e-6
    print(f"\nJansen leg verified in {report.seconds:.2f} s")


@pytest.mark.parametrize("flat", [False, True])
def test_least_clearance_is_the_least_over_every_pair_and_pose(
    jansen_export: Path, tmp_path: Path, flat: bool
) -> None:
    """The clearance check measures pairs nearest box first and stops where no box comes
    nearer: its figure is still the least of every pair at every pose (the deepest overlap
    where parts cross: every plate on one layer), and boxes apart hold parts at least as far
    apart."""
    folder = planted(jansen_export, tmp_path)
    if flat:
        edit_model(folder, _flatten)
    model = mujoco.MjModel.from_xml_path(str(folder / "mechanism.xml"))
    data = mujoco.MjData(model)
    poses = solve_sweep(model, data, np.arange(40) * (2 * np.pi / 40))
    size = 1.0
    pairs, _ = classify_pairs(model, size)
    g1, g2 = (np.array([pair[k] for pair in pairs]) for k in (0, 1))
    least = np.inf
    for qpos in poses:
        data.qpos[:] = qpos
        mujoco.mj_kinematics(model, data)
        exact = [mujoco.mj_geomDistance(model, data, int(a), int(b), size, None)
                 for a, b in pairs]  # fmt: skip
        assert (box_distances(model, data, g1, g2) <= np.maximum(exact, 0) + 1e-12).all()
        least = min(least, *exact)
    check = check_collisions(model, poses, size, None)
    assert check.figure == least and (least < 0) == flat


def _flatten(root: ET.Element) -> None:
    """Every plate on the base's layer."""
    for geom in root.iter("geom"):
        if geom.get("type") == "mesh":
            x, y, _ = geom.get("pos", "0 0 0").split()
            geom.set("pos", f"{x} {y} 0")


def test_plates_on_one_layer_collide(jansen_export: Path, tmp_path: Path) -> None:
    folder = planted(jansen_export, tmp_path)
    edit_model(folder, _flatten)
    report = verify_output(folder)
    assert not report.passed and "collisions" in report.failed
    collisions = next(c for c in report.checks if c.name == "collisions")
    assert "contact" in collisions.detail and "deg" in collisions.detail
    # the dynamic run looks for contacts after each step and stops at the first
    dynamics = next(c for c in report.checks if c.name == "dynamics")
    assert "stopped at a contact" in dynamics.detail and "(dynamic run)" in collisions.detail


def test_removed_loop_closure_frees_a_joint(jansen_export: Path, tmp_path: Path) -> None:
    folder = planted(jansen_export, tmp_path)

    def drop_loop(root: ET.Element) -> None:
        equality = root.find("equality")
        equality.remove(equality.find("connect"))

    edit_model(folder, drop_loop)
    report = verify_output(folder)
    assert "mobility" in report.failed
    mobility = next(c for c in report.checks if c.name == "mobility")
    assert "3 degrees of freedom" in mobility.detail  # a pin in the plane holds two


def test_design_file_off_the_model(jansen_export: Path, tmp_path: Path) -> None:
    folder = planted(jansen_export, tmp_path)
    mech = Mechanism.load(folder / "mechanism.json")
    moved = mech.positions.copy()
    moved[2] += [0.5, 0.0]  # the frame pivot, half a millimetre
    mech.replace(positions=moved).save(folder / "mechanism.json")
    report = verify_output(folder)
    assert "kinematics" in report.failed
    assert {c.name for c in report.checks if c.passed} >= {"load", "mobility"}


def test_collision_hidden_by_the_model_is_caught(jansen_export: Path, tmp_path: Path) -> None:
    folder = planted(jansen_export, tmp_path)

    def hide(root: ET.Element) -> None:
        plate = next(g for g in root.iter("geom") if g.get("name") == "link_1_3")
        plate.set("contype", "0")
        plate.set("conaffinity", "0")

    edit_model(folder, hide)
    report = verify_output(folder)
    assert report.failed == ["collisions"]
    collisions = next(c for c in report.checks if c.name == "collisions")
    assert "excluded from contact but not a pin in its hole: link_1_3" in collisions.detail


@pytest.mark.parametrize("edit", ["moved", "scaled", "boxes moved"])
def test_a_plate_edited_off_its_pins_fails(jansen_export: Path, tmp_path: Path, edit) -> None:
    """The joints still move as designed, but the link no longer reaches them."""
    if edit == "boxes moved":  # the model without meshes: the link's bar and bosses
        from linkd.export import export_mechanism

        folder = tmp_path / "boxes"
        folder.mkdir()
        export_mechanism(Mechanism.load(EXAMPLES / "jansen_leg.json"), folder, {"mjcf"})
    else:
        folder = planted(jansen_export, tmp_path)
    mech = Mechanism.load(folder / "mechanism.json")
    width = resolve_sizes(mech, assemble(mech).parts, None).link_width * 1e-3  # metres

    def move(root: ET.Element) -> None:
        for geom in root.iter("geom"):
            name = geom.get("name") or ""
            if edit == "scaled" and name == "link_1_4":
                mesh = next(m for m in root.iter("mesh") if m.get("name") == geom.get("mesh"))
                mesh.set("scale", "0.3 0.3 1")
            elif name == "link_1_4" or name.startswith("link_1_4_"):
                x, y, z = map(float, geom.get("pos").split())
                geom.set("pos", f"{x + 0.4 * width} {y} {z}")

    edit_model(folder, move)
    report = verify_output(folder)
    assert "load" in report.failed
    load = next(c for c in report.checks if c.name == "load")
    assert "part link_1_4 does not hold its pin" in load.detail


def test_soft_loop_closures_fail_the_dynamic_run(jansen_export: Path, tmp_path: Path) -> None:
    folder = planted(jansen_export, tmp_path)

    def soften(root: ET.Element) -> None:
        root.find("default").find("equality").set("solref", "0.05 1")

    edit_model(folder, soften)
    report = verify_output(folder)
    assert report.failed == ["dynamics"]
    dynamics = next(c for c in report.checks if c.name == "dynamics")
    assert "loop violation" in dynamics.detail and dynamics.figure > 1e-6


def test_missing_contract_name(tmp_path: Path, capsys) -> None:
    mech = scaled(crank_rocker())
    folder = hand_built(tmp_path / "out", mech)
    text = (folder / "mechanism.xml").read_text().replace('"end_effector"', '"tip"')
    (folder / "mechanism.xml").write_text(text)
    assert main(["verify", str(folder)]) == 1
    report = json.loads((folder / "report.json").read_text())["verification"]
    assert report["failed"] == ["load", "mobility", "kinematics", "dynamics", "collisions"]
    assert "no site named 'end_effector'" in report["checks"][0]["detail"]
    assert {c["status"] for c in report["checks"][1:]} == {"skip"}


def test_hand_built_four_bar_passes(tmp_path: Path) -> None:
    """An independent model of the same contract passes every check."""
    folder = hand_built(tmp_path / "out", scaled(crank_rocker()))
    report = verify_output(folder)
    assert report.passed, [(c.name, c.detail) for c in report.checks]


def test_link_that_locks(tmp_path: Path) -> None:
    folder = hand_built(tmp_path / "out", scaled(non_grashof_four_bar()))
    report = verify_output(folder)
    assert not report.passed and "mobility" in report.failed
    mobility = next(c for c in report.checks if c.name == "mobility")
    assert "locks" in mobility.detail
    dynamics = next(c for c in report.checks if c.name == "dynamics")
    assert not dynamics.passed  # the servo cannot drive it through a revolution either


@pytest.mark.parametrize("name", ["crank_rocker", "watt_six_bar", "stephenson_six_bar"])
def test_shipped_examples_pass(name: str, tmp_path: Path) -> None:
    from linkd.export import export_mechanism

    export_mechanism(Mechanism.load(EXAMPLES / f"{name}.json"), tmp_path, {"mjcf", "stl"})
    report = verify_output(tmp_path)
    assert report.passed, [(c.name, c.detail) for c in report.checks]


# ---- command line ------------------------------------------------------------------------------


def test_cli_exit_status(jansen_export: Path, tmp_path: Path, capsys) -> None:
    good = planted(jansen_export, tmp_path)
    assert main(["verify", str(good)]) == 0
    assert "verified" in capsys.readouterr().out
    bad = hand_built(tmp_path / "locks", scaled(non_grashof_four_bar()))
    assert main(["verify", str(bad)]) == 1
    assert "failed: mobility" in capsys.readouterr().out


def test_cli_refuses_bad_input(tmp_path: Path, capsys) -> None:
    assert main(["verify", str(tmp_path / "missing")]) == 2
    (tmp_path / "curve.csv").write_text("0,0\n")
    assert main(["verify", str(tmp_path / "curve.csv")]) == 2
    assert "is a file, not an output folder" in capsys.readouterr().err
    folder = hand_built(tmp_path / "out", scaled(crank_rocker()))
    (folder / "mechanism.xml").unlink()
    assert main(["verify", str(folder)]) == 2
    err = capsys.readouterr().err
    assert "mechanism.xml: missing" in err and len(err.strip().splitlines()) == 1
    (folder / "mechanism.xml").write_text(four_bar_xml(scaled(crank_rocker())))
    (folder / "mechanism.json").write_text("{not json")
    assert main(["verify", str(folder)]) == 2
    assert not (folder / "report.json").exists()
