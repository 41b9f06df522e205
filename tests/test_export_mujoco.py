"""The exported model in MuJoCo: it loads cleanly, moves with one freedom, closes its loops,
follows the analytic path and never collides (CONTRACT §3)."""

from pathlib import Path

import mujoco
import numpy as np
import pytest

from linkd import classic
from linkd.export import ExportOptions, export_mechanism, joint_paths, qpos_at
from linkd.export.layers import Layout, assign_layers, sweep
from linkd.export.mjcf import build_mjcf
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.geometry import Similarity
from linkd.graph import from_graph
from linkd.mechanism import UNITS_IN_METRES, Mechanism
from linkd.verify.checks import capture_warnings
from linkd.verify.pose import loop_closure, solve_pose

EXAMPLES = Path(__file__).resolve().parents[1] / "assets" / "examples"
N_ANGLES = 200
RAMP_S, HOLD_S = 2.0, 0.5


def _generated(count: int = 3) -> list[Mechanism]:
    """Random generated mechanisms at a realistic size (tens of mm) that can be built flat."""
    from linkd.generator import GeneratorSettings, generate

    samples = generate(2 * count, 7, GeneratorSettings(max_nodes=9, batch=64))
    found = []
    for graph in samples.graphs:
        mech = from_graph(graph, Similarity(40.0))
        assembly = assemble(mech)
        sizes = resolve_sizes(mech, assembly.parts, None)
        try:
            assign_layers(assembly, sweep(mech, sizes.link_width), sizes)
        except ValueError:
            continue
        found.append(mech)
    assert len(found) >= count, "too few generated mechanisms can be built from flat layers"
    return found[:count]


def _cases() -> dict:
    names = ("jansen_leg", "crank_rocker", "watt_six_bar", "stephenson_six_bar")
    both = {"mjcf", "stl"}
    cases = {name: (Mechanism.load(EXAMPLES / f"{name}.json"), both, None) for name in names}
    cases["jansen_primitives"] = (cases["jansen_leg"][0], {"mjcf"}, None)
    cases["millimetre_crank_rocker"] = (classic.crank_rocker(), both, None)  # 1 mm crank
    # 0.12 mm across: its parts' gaps are microns, near MuJoCo's own mesh distance tolerance
    cases["tenth_millimetre_crank_rocker"] = (
        classic.crank_rocker().transformed(Similarity(0.03)),
        both,
        None,
    )
    # plates 1.5 um wide: meshes under MuJoCo's volume floor for an exact inertia
    cases["thin_plates"] = (classic.crank_rocker(), both, ExportOptions(link_width=0.0015))
    for k, mech in enumerate(_generated()):
        cases[f"generated_{k}"] = (mech, both, None)
    return cases


CASES = _cases()


@pytest.fixture(scope="module", params=sorted(CASES))
def exported(request, tmp_path_factory):
    mech, formats, options = CASES[request.param]
    out = tmp_path_factory.mktemp(request.param)
    export_mechanism(mech, out, formats, options)
    with capture_warnings() as messages:
        model = mujoco.MjModel.from_xml_path(str(out / "mechanism.xml"))
    return mech, model, messages, out


def _loops(model):
    """(site1, site2) of every connect equality."""
    assert np.all(model.eq_type == mujoco.mjtEq.mjEQ_CONNECT)
    assert np.all(model.eq_objtype == mujoco.mjtObj.mjOBJ_SITE)
    return np.stack([model.eq_obj1id, model.eq_obj2id], 1)


def _metres(mech):
    return UNITS_IN_METRES[mech.units]


def test_model_loads_without_warnings_with_the_contract_names(exported):
    _, model, messages, out = exported
    assert messages == []
    assert model.actuator("motor").trnid[0] == model.joint("crank").id
    assert model.actuator_ctrllimited[0] == 0
    assert np.all(model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)
    assert np.allclose(model.jnt_axis, [0, 0, 1])
    assert model.site("end_effector").id >= 0
    assert model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_FILTERPARENT
    assert not any(mujoco.mjtGeom(k).name == "mjGEOM_CAPSULE" for k in model.geom_type)
    with capture_warnings() as scene_messages:
        mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
    assert scene_messages == []


def test_random_motor_noise_for_one_second(exported):
    """The Menagerie test: filtered random controls, no warning, nothing blows up."""
    _, model, _, _ = exported
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    with capture_warnings() as messages:
        for _ in range(round(1.0 / model.opt.timestep)):
            data.ctrl[:] = 0.95 * data.ctrl + 0.05 * rng.normal(0.0, 2.0, model.nu)
            mujoco.mj_step(model, data)
    assert messages == [] and all(w.number == 0 for w in data.warning)
    assert np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all()


def test_held_crank_poses_match_the_analytic_path_with_one_freedom(exported):
    mech, model, _, _ = exported
    data = mujoco.MjData(model)
    angles = np.arange(N_ANGLES) * (2 * np.pi / N_ANGLES)
    analytic = qpos_at(model, mech, angles)
    path = joint_paths(mech, angles)[mech.end_effector] * _metres(mech)
    size = mech.scale * _metres(mech)
    crank = model.joint("crank").qposadr[0]
    free = np.arange(model.nv) != crank
    ee = model.site("end_effector").id
    for angle, guess, target in zip(angles, analytic, path):
        qpos = solve_pose(model, data, angle, qpos0=guess)
        assert np.abs(np.angle(np.exp(1j * (qpos - guess)))).max() < 1e-6
        _, jacobian = loop_closure(model, data, qpos)
        tol = 1e-9 * np.abs(jacobian).max()
        assert model.nv - np.linalg.matrix_rank(jacobian, tol) == 1
        assert np.linalg.matrix_rank(jacobian[:, free], tol) == model.nv - 1
        mujoco.mj_forward(model, data)
        assert data.ncon == 0
        assert np.linalg.norm(data.site_xpos[ee, :2] - target) <= 1e-9 * size


def test_motor_ramp_turns_the_crank_once_with_closed_loops(exported):
    mech, model, _, _ = exported
    data = mujoco.MjData(model)
    loops = _loops(model)
    crank = model.joint("crank").qposadr[0]
    ee = model.site("end_effector").id
    steps = round((RAMP_S + HOLD_S) / model.opt.timestep)
    angle, ends, violation = np.zeros(steps), np.zeros((steps, 2)), np.zeros(steps)
    with capture_warnings() as messages:
        for k in range(steps):
            data.ctrl[0] = 2 * np.pi * min(data.time / RAMP_S, 1.0)
            mujoco.mj_step(model, data)
            mujoco.mj_kinematics(model, data)  # positions of the new state, not of an RK stage
            angle[k], ends[k] = data.qpos[crank], data.site_xpos[ee, :2]
            gaps = data.site_xpos[loops[:, 0], :2] - data.site_xpos[loops[:, 1], :2]
            violation[k] = np.linalg.norm(gaps, axis=1).max(initial=0.0)
    assert messages == [] and all(w.number == 0 for w in data.warning)
    assert np.isfinite(ends).all()
    assert abs(angle[-1] - 2 * np.pi) < 1e-2
    shortest = mech.link_lengths().min() * _metres(mech)
    assert violation.max() < 1e-6 * shortest
    path = joint_paths(mech, angle)[mech.end_effector] * _metres(mech)
    radius = np.sqrt(((path - path.mean(0)) ** 2).sum(1).mean())
    assert np.linalg.norm(ends - path, axis=1).max() < 1e-5 * radius


def _sweep_contacts(xml: Path, mech: Mechanism) -> int:
    model = mujoco.MjModel.from_xml_path(str(xml))
    data = mujoco.MjData(model)
    most = 0
    for qpos in qpos_at(model, mech, np.arange(N_ANGLES) * (2 * np.pi / N_ANGLES)):
        data.qpos[:] = qpos
        mujoco.mj_forward(model, data)
        most = max(most, data.ncon)
    return most


def test_planted_defects_are_caught(tmp_path):
    """All plates on one layer collide; a loop closure removed frees two more degrees."""
    mech = Mechanism.load(EXAMPLES / "jansen_leg.json")
    assembly = assemble(mech)
    sizes = resolve_sizes(mech, assembly.parts, None)
    flat = Layout(np.array([0] + [1] * (len(assembly.parts) - 1)),
                  [(0, 1)] * len(assembly.pins), (), 2, 0.0)  # fmt: skip
    xml = tmp_path / "flat.xml"
    xml.write_text(build_mjcf(mech, assembly, flat, sizes))
    assert _sweep_contacts(xml, mech) > 0
    export_mechanism(mech, tmp_path, {"mjcf"})
    assert _sweep_contacts(tmp_path / "mechanism.xml", mech) == 0
    text = (tmp_path / "mechanism.xml").read_text()
    start = text.index("<connect")
    (tmp_path / "open.xml").write_text(text[:start] + text[text.index("/>", start) + 2 :])
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "open.xml"))
    qpos = qpos_at(model, mech, np.array([1.0]))[0]
    _, jacobian = loop_closure(model, mujoco.MjData(model), qpos)
    assert model.nv - np.linalg.matrix_rank(jacobian, 1e-9 * np.abs(jacobian).max()) == 3


def test_plates_under_the_mesh_volume_floor_keep_their_solid_mass(tmp_path):
    """MuJoCo refuses an exact inertia for a mesh under 1e-15 m^3: such plates (a 1.5 um wide
    crank) take a shell inertia and the mass of their solid, so the model still compiles."""
    import trimesh

    options = ExportOptions(link_width=0.0015)
    result = export_mechanism(classic.crank_rocker(), tmp_path, {"mjcf", "stl"}, options)
    text = (tmp_path / "mechanism.xml").read_text()
    assert '<mesh name="link_0_1" file="meshes/link_0_1.stl" inertia="shell" />' in text
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "mechanism.xml"))
    volume = trimesh.load(tmp_path / "meshes" / "link_0_1.stl").volume
    assert 0 < volume < mujoco.mjMINVAL
    density = result.sizes["density"]  # raised clear of MuJoCo's mass floor
    assert density > 1200
    assert model.body("link_0_1").mass[0] == pytest.approx(density * volume, rel=1e-6)
