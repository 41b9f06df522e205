"""Split cranks on a ground bracket (linkd.export.braced): a mechanism that neither straight nor
bent links can layer built and verified, and planted collisions of its arms and bracket caught."""

import xml.etree.ElementTree as ET

import pytest
import trimesh
from test_export_narrow import KNOTTED

from linkd.export import ExportOptions, buildable, export_mechanism
from linkd.export.layers import assign_layers, sweep
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.export.routing import bent_layers
from linkd.verify import verify_output


@pytest.fixture(scope="module")
def braced(tmp_path_factory):
    out = tmp_path_factory.mktemp("braced")
    return out, export_mechanism(KNOTTED, out, {"mjcf", "stl"})


def test_refused_flat_and_bent_is_built_split_on_a_bracket_and_verified(braced):
    out, result = braced
    assembly = assemble(KNOTTED)
    sizes = resolve_sizes(KNOTTED, assembly.parts, None)
    paths = sweep(KNOTTED, sizes.link_width)
    for layering in (assign_layers, bent_layers):
        with pytest.raises(ValueError, match="flat layers"):
            layering(assembly, paths, sizes)
    parts = {p["name"]: p for p in result.parts}
    arms = [p for p in result.parts if p.get("arm_of") == "plate_0_1_2"]
    assert sorted(tuple(p["joints"]) for p in arms) == [(0, 1), (0, 2)]
    assert len({p["layer"] for p in arms}) == 2  # one arm each side of the bracket
    bracket, post = parts["ground_bracket0"], parts["ground_post0"]
    assert bracket["joints"] == [0] and bracket["posts"] == [post["at"]]
    assert min(p["layer"] for p in arms) < bracket["layer"] < max(p["layer"] for p in arms)
    base = parts["ground_cover" if post["layers"][1] > bracket["layer"] else "ground"]
    assert post["at"] in base["posts"] and bracket["layer"] in post["layers"]
    assert parts["pin_0"]["fixed_in"] == "plate_0_1_2"
    for part in result.parts:  # every plate a solid; every pin reaches the plates it joins
        if "mesh" in part:
            solid = trimesh.load(out / part["mesh"])
            assert solid.is_watertight and solid.is_volume
        if part["kind"] == "pin":
            lo, hi = part["layers"]
            holes = [p["layer"] for p in result.parts if "layer" in p and p["kind"] != "pin"
                     and part["joints"][0] in p["joints"]]  # fmt: skip
            assert min(holes) == lo and max(holes) == hi
    report = verify_output(out, write=False)
    assert report.passed, report.failed


def _moved(out, name: str, z: float | None = None, xy: tuple | None = None) -> ET.ElementTree:
    tree = ET.parse(out / "mechanism.xml")
    geom = next(g for g in tree.iter("geom") if g.get("name") == name)
    x, y, height = map(float, geom.get("pos").split())
    x, y = xy or (x, y)
    geom.set("pos", f"{x} {y} {height if z is None else z}")
    return tree


def _z(out, name: str) -> float:
    tree = ET.parse(out / "mechanism.xml")
    return float(next(g for g in tree.iter("geom") if g.get("name") == name).get("pos").split()[2])


@pytest.mark.parametrize("plant", ["arm", "bracket", "post"])
def test_a_planted_collision_in_the_split_crank_or_its_bracket_is_caught(braced, tmp_path, plant):
    """An arm laid on the layer of the coupler that sweeps over it, the bracket laid on an
    arm's layer, or the post set down at the pivot: verification must name the part."""
    out, result = braced
    parts = {p["name"]: p for p in result.parts}
    for path in out.iterdir():
        (tmp_path / path.name).symlink_to(path)
    (tmp_path / "mechanism.xml").unlink()
    if plant == "arm":  # the arm to joint 2 onto the layer of the link at joint 1
        arm = next(p["name"] for p in result.parts if p.get("joints") == [0, 2])
        name, tree = arm, _moved(out, arm, z=_z(out, "link_1_6"))
    elif plant == "bracket":
        arm = next(p["name"] for p in result.parts if p.get("joints") == [0, 1])
        name, tree = "ground_bracket0", _moved(out, "ground_bracket0", z=_z(out, arm))
    else:
        arm = next(p for p in result.parts if p.get("joints") == [0, 1])
        lo, hi = parts["ground_post0"]["layers"]
        assert lo <= arm["layer"] <= hi  # the post crosses the arm's layer
        x, y = KNOTTED.positions[[0, 1]].mean(0) * 1e-3  # across the arm to joint 1, metres
        name, tree = "ground_post0", _moved(out, "ground_post0", xy=(x, y))
    tree.write(tmp_path / "mechanism.xml")
    report = verify_output(tmp_path, write=False)
    assert "collisions" in report.failed
    detail = next(c.detail for c in report.checks if c.name == "collisions")
    assert name in detail


def test_without_brackets_the_same_mechanism_is_refused(tmp_path):
    """What a design run past its time budget asks for: the slow construction left out."""
    assert buildable(KNOTTED)
    assert not buildable(KNOTTED, ExportOptions(brackets=False))
    with pytest.raises(ValueError, match="flat layers"):
        export_mechanism(KNOTTED, tmp_path, {"mjcf"}, ExportOptions(brackets=False))
