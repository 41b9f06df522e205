"""Bent links (linkd.export.routing): routes round pin paths, a mechanism that straight links
cannot layer built and verified, a straightened bent link caught by verification, and what a
refusal says."""

import re
import xml.etree.ElementTree as ET
from dataclasses import replace

import numpy as np
import pytest
import trimesh
from planted import collision_detail
from test_export_narrow import STUBBORN, TANGLED

from linkd.export import NARROWER, ExportOptions, export_mechanism
from linkd.export.layers import NoFlatLayers, assign_layers, find_conflicts, stack_layers, sweep
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.export.routing import clearance, route
from linkd.verify import verify_output

CIRCLE = np.exp(1j * np.linspace(0, 2 * np.pi, 200, endpoint=False))


def _ring(centre: complex, radius: float) -> np.ndarray:
    z = centre + radius * CIRCLE
    return np.stack([z.real, z.imag], -1)


def test_a_route_goes_round_a_pin_path_with_the_reach_to_spare():
    ends = np.array([[0.0, 0.0], [10.0, 0.0]])
    pin = _ring(5 + 0.5j, 1.0)  # the pin circles across the straight link
    waypoints = route(ends, [pin], reach=1.5)
    assert waypoints is not None and 1 <= len(waypoints) <= 3
    chain = np.concatenate([ends[:1], waypoints, ends[1:]])
    segments = (pin[:, 0] + 1j * pin[:, 1], np.roll(pin[:, 0] + 1j * pin[:, 1], -1))
    assert clearance(chain, segments) >= 1.5
    assert route(ends, [_ring(20j, 1.0)], reach=1.5).shape == (0, 2)  # clear: straight


def test_no_route_when_the_pin_circles_a_joint():
    ends = np.array([[0.0, 0.0], [10.0, 0.0]])
    assert route(ends, [_ring(0j, 3.0)], reach=1.0) is None


@pytest.fixture(scope="module")
def bent(tmp_path_factory):
    """TANGLED at its default width, which straight links cannot layer."""
    out = tmp_path_factory.mktemp("bent")
    width = resolve_sizes(TANGLED, assemble(TANGLED).parts, None).link_width
    result = export_mechanism(TANGLED, out, {"mjcf", "stl"}, ExportOptions(link_width=width))
    return out, result, width


def test_straight_links_refused_are_built_bent_and_verified(bent):
    out, result, width = bent
    assembly = assemble(TANGLED)
    sizes = resolve_sizes(TANGLED, assembly.parts, ExportOptions(link_width=width))
    with pytest.raises(ValueError, match="flat layers"):
        assign_layers(assembly, sweep(TANGLED, width), sizes)
    assert result.sizes["link_width"] == pytest.approx(width)
    bent_links = [p for p in result.parts if "bends" in p]
    assert bent_links and all(p["kind"] == "link" for p in bent_links)
    for part in bent_links:
        solid = trimesh.load(out / part["mesh"])
        assert solid.is_watertight and solid.is_volume
        assert len(part["pieces"]) == len(part["bends"]) + 1
        assert all((out / piece).is_file() for piece in part["pieces"])
    report = verify_output(out, write=False)
    assert report.passed, report.failed


def test_a_straightened_bent_link_is_caught(bent, tmp_path):
    """Without STL the bars are boxes: laid straight between its bosses, a bent link passes
    over the pin it went round, and verification must say so."""
    export_mechanism(TANGLED, tmp_path, {"mjcf"}, ExportOptions(link_width=bent[2]))
    assert verify_output(tmp_path, write=False).passed
    tree = ET.parse(tmp_path / "mechanism.xml")
    geoms = {g.get("name"): g for g in tree.iter("geom")}
    a, b = (np.array(geoms[f"link_2_3_boss{j}"].get("pos").split(), float) for j in (2, 3))
    bar = geoms["link_2_3_bar0"]
    d = b - a
    bar.set("pos", " ".join(map(str, (a + b) / 2)))
    bar.set("size", " ".join([str(np.hypot(*d[:2]) / 2), *bar.get("size").split()[1:]]))
    bar.set("euler", f"0 0 {np.arctan2(d[1], d[0])}")
    assert "link_2_3_bar0" in collision_detail(tree, tmp_path)


def test_what_bending_cannot_save_is_refused_in_one_line(tmp_path):
    message = (r"straight, bent, strapped, split and forked parts, turntables, ground rings, "
               r"down to 0\.25")  # fmt: skip
    with pytest.raises(ValueError, match=message) as refusal:
        export_mechanism(STUBBORN, tmp_path, {"mjcf"})
    assert "\n" not in str(refusal.value)


def test_a_refusal_names_pins_and_parts_that_alone_cannot_be_kept_clear(tmp_path):
    """The pins named, each kept off the parts named with it, can be built round by no stack of
    straight parts at the narrowest width, and each pin and each part is needed for that:
    without any one, the rest layer."""
    with pytest.raises(ValueError) as refusal:
        export_mechanism(STUBBORN, tmp_path, {"mjcf"})
    named = re.search(r"with straight parts, (.*) alone cannot", str(refusal.value)).group(1)
    passing = dict(re.findall(r"(pin_\d+) \(passed by ([^)]*)\)", named))
    assembly = assemble(STUBBORN)
    usual = resolve_sizes(STUBBORN, assembly.parts, None).link_width
    sizes = resolve_sizes(STUBBORN, assembly.parts, ExportOptions(link_width=usual * NARROWER[-1]))
    conflicts = find_conflicts(assembly, sweep(STUBBORN, sizes.link_width), sizes)
    pins = {pin.name: k for k, pin in enumerate(assembly.pins)}
    parts = {part.name: q for q, part in enumerate(assembly.parts)}
    blocked = {pin: [parts[name] for name in names.split(", ")] for pin, names in passing.items()}
    assert 2 <= len(blocked) < len(assembly.pins)
    assert set(re.findall(r"pin_\d+", named)) == set(blocked)  # every pin named with its parts
    for pin, kept in blocked.items():
        assert set(kept) <= set(conflicts.blocked[pins[pin]])

    def layer(chosen_blocked: dict[str, list[int]]) -> None:
        chosen = replace(assembly, pins=[assembly.pins[pins[name]] for name in chosen_blocked])
        stack_layers(chosen, replace(conflicts, blocked=list(chosen_blocked.values())), sizes)

    with pytest.raises(NoFlatLayers):
        layer(blocked)
    for name in blocked:
        layer({other: kept for other, kept in blocked.items() if other != name})
        for q in blocked[name]:
            layer({**blocked, name: [r for r in blocked[name] if r != q]})
