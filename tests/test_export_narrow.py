"""Mechanisms the default link width cannot layer: narrower links, refusals, and what
`linkd design` counts when it passes a better design over."""

import re

import numpy as np
import pytest

from linkd.design.output import deliver
from linkd.export import export_mechanism
from linkd.export.layers import assign_layers, sweep
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.mechanism import Mechanism
from linkd.verified import export_verified
from linkd.verify import verify_output

# Generated (seed 2026, no. 19): the coupler sweeps over the crank pivot and the crank tip over
# the rocker; at the default width no order of flat layers keeps every pin clear.
TANGLED = Mechanism(
    [(30.033, 43.479), (18.14, 24.021), (17.776, 8.193), (-70.562, 1.442), (5.57, 14.007),
     (67.198, 72.843)],
    [1, 0, 1, 0, 0, 0], [(0, 1), (0, 4), (1, 3), (2, 3), (3, 4), (3, 5), (4, 5)], (0, 1), 5,
)  # fmt: skip

# Generated (seed 2026, no. 80): a ternary crank whose two couplers each sweep over the other's
# pin and over the pivot: no flat layering at any width linkd tries, straight or bent (it is
# built with a link on a sheave, or with straps off the crank split on a ground bracket,
# test_export_braced).
KNOTTED = Mechanism(
    [(48.349, 73.281), (86.18, 96.902), (35.808, 91.922), (-62.988, 87.08), (-58.152, 9.109),
     (80.968, -67.956), (44.982, -77.361), (67.468, -0.151)],
    [1, 0, 0, 1, 0, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 6), (2, 4), (2, 7), (3, 4), (3, 5), (3, 6), (4, 5), (4, 7)],
    (0, 1), 7,
)  # fmt: skip

# Generated (`generate(40, 22, GeneratorSettings(min_nodes=7, max_nodes=10))`, no. 17, scaled
# to 100 mm): links 1-3, 1-4 and 1-7 hang on the crank tip and sweep over the ground pivots 0
# and 2 and over each other's pins; no flat layering at any width, straight, bent, strapped,
# split on a bracket or forked: it is built with the crank on a turntable.
SNARLED = Mechanism(
    [(38.1, 38.3), (66.1, 44.5), (-63.8, 43.2), (-17.7, -4.5), (66.1, -72.6), (-13.9, 35.8),
     (-50.2, -92.8), (65.6, 93.1), (71.9, 26.2), (21.5, 59.6)],
    [1, 0, 1, 0, 0, 1, 0, 0, 0, 0],
    [(0, 1), (0, 4), (1, 3), (1, 4), (1, 7), (2, 3), (3, 7), (4, 6), (4, 8), (4, 9), (5, 6),
     (7, 8), (8, 9)],
    (0, 1), 9,
)  # fmt: skip

# Generated (`generate(200, 159, GeneratorSettings(min_nodes=7, max_nodes=11))`, no. 18,
# scaled to 100 mm): a design with no joint to prune that no construction builds. (Seed 2026's
# no. 243, its end effector's sub-mechanism, refused here before, is built since parts turn on
# sheaves; `generate(100, 11)`'s no. 11 since then too, seed 2026's no. 63 since parts fork,
# SNARLED since the crank turns on a turntable, and `generate(40, 56, ...)`'s no. 30 since the
# crank may be cut in two.)
STUBBORN = Mechanism(
    [(20.0, -8.5), (-0.7, -40.8), (-56.3, -52.7), (97.4, -86.9), (53.0, 51.4), (-6.3, 2.9),
     (50.6, -77.2), (37.3, 34.7), (-12.6, -36.3), (-82.1, 46.3), (-57.7, -76.5)],
    [1, 0, 0, 1, 0, 1, 0, 0, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 4), (1, 7), (2, 9), (3, 4), (3, 7), (3, 8), (4, 6), (5, 6),
     (6, 10), (7, 8), (8, 9), (9, 10)], (0, 1), 10,
)  # fmt: skip


def test_refused_at_the_default_width_is_built_with_narrower_links_and_verified(tmp_path):
    assembly = assemble(TANGLED)
    default = resolve_sizes(TANGLED, assembly.parts, None)
    with pytest.raises(ValueError, match="flat layers"):
        assign_layers(assembly, sweep(TANGLED, default.link_width), default)
    told = []
    result = export_mechanism(TANGLED, tmp_path, progress=told.append)
    assert told == ["layering straight parts at the usual width",
                    "layering straight parts at 0.5 of the usual width",
                    f"writing {result.layers} layers of parts"]  # fmt: skip
    assert result.sizes["link_width"] == pytest.approx(default.link_width / 2)
    assert result.sizes["hole_diameter"] == pytest.approx(default.hole_diameter / 2)
    report = verify_output(tmp_path, write=False)
    assert report.passed, report.failed


def test_export_says_when_its_links_are_narrower(tmp_path, capsys):
    from linkd.cli import main

    mech = tmp_path / "tangled.json"
    TANGLED.save(mech)
    assert main(["export", str(mech), "--out", str(tmp_path / "out"), "--export", "mjcf"]) == 0
    usual = resolve_sizes(TANGLED, assemble(TANGLED).parts, None).link_width
    said = capsys.readouterr().out
    assert f"links {usual / 2:.3g} mm wide, 0.5 of the usual width" in said
    assert main(["export", str(mech), "--out", str(tmp_path / "given"),
                 "--export", "mjcf", "--link-width", f"{usual / 2}"]) == 0  # fmt: skip
    assert "usual width" not in capsys.readouterr().out  # a width the user gave is the usual one


def test_a_width_the_user_gives_is_kept(tmp_path):
    from linkd.export import ExportOptions

    width = resolve_sizes(STUBBORN, assemble(STUBBORN).parts, None).link_width
    with pytest.raises(ValueError, match="flat layers") as refusal:
        export_mechanism(STUBBORN, tmp_path, {"mjcf"}, ExportOptions(link_width=width))
    assert "usual width" not in str(refusal.value)  # no narrower width was tried


def test_no_width_layers_it_and_design_counts_the_skip(tmp_path):
    told = []
    with pytest.raises(ValueError, match=r"0\.25 of the usual width"):
        export_mechanism(STUBBORN, tmp_path, {"mjcf"}, progress=told.append)
    widths = ("the usual width", "0.5 of the usual width", "0.25 of the usual width")
    plain = [f"layering {c} at {w}" for c in ("straight parts", "bent links", "eccentric straps")
             for w in widths]  # fmt: skip
    # the costly ones skip half the width where a quarter does not layer
    costly = ("split plates and brackets", "forked parts", "turntables at the motor's pivot")
    screened = [f"layering {c} at {w}" for c in costly for w in widths[::2]]
    last = [f"layering {c} at {w}" for c in ("several eccentric straps at once",
            "a turntable with several straps") for w in widths]  # fmt: skip
    split = [f"layering {c} at {w}" for c in ("split plates with straps",
             "a crank cut in two, driven from a layshaft", "ground pivots on rings",
             "ground pivots on rings beside forked parts",
             "the crank on a ring beside forked parts", "straps beside forked parts")
             for w in widths[::2]]  # fmt: skip
    why = ["none layers: finding the pins that keep it from layering"]
    assert told == plain + screened + last + split + why
    passed = []
    t = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    target = STUBBORN.positions[STUBBORN.end_effector] + 10 * np.c_[np.cos(t), np.sin(t)]
    assert deliver(STUBBORN, target, tmp_path, {"mjcf"}, {}, passed=passed) is None
    assert [p.reason for p in passed] == ["unbuildable"]
    assert not list(tmp_path.iterdir())


def test_planted_collision_in_a_two_plate_ground_is_caught(tmp_path):
    """The ground of this mechanism is a base plate plus a cover plate over the stack: lowered
    into the stack, the cover sweeps through moving plates and verification must say so."""
    from test_export import CRANK_PLATE

    export_mechanism(CRANK_PLATE, tmp_path, {"mjcf", "stl"})
    assert verify_output(tmp_path, write=False).passed
    xml = tmp_path / "mechanism.xml"
    text = xml.read_text()
    cover = re.search(r'<geom name="ground_cover"[^>]*pos="0 0 ([^"]+)"', text)
    assert cover is not None
    lowered = float(cover.group(1)) / 2  # the middle of the stack
    xml.write_text(text.replace(cover.group(0), cover.group(0).replace(
        f'pos="0 0 {cover.group(1)}"', f'pos="0 0 {lowered:.12g}"')))  # fmt: skip
    report = verify_output(tmp_path, write=False)
    assert "collisions" in report.failed


# Generated (seed 2026, no. 103 of 200, scaled to 100 mm): no construction layers it at the
# usual width; split plates and brackets do at a quarter of it, not at half of it.
QUARTERED = Mechanism(
    [(-39.694, -17.689), (-22.672, -38.768), (-71.457, -83.274), (-80.267, 26.146),
     (31.015, 75.215), (49.055, -65.088), (-19.621, -98.023), (44.129, 63.307), (56.764, 22.542),
     (-28.223, -48.311), (-82.102, 42.635), (-78.456, -39.159)],
    [1, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0],
    [(0, 1), (0, 7), (1, 3), (1, 4), (1, 7), (2, 3), (2, 8), (3, 4), (3, 6), (3, 9), (5, 6),
     (6, 8), (6, 10), (6, 11), (7, 10), (8, 9), (10, 11)],
    (0, 1), 11,
)  # fmt: skip


def test_a_costly_construction_is_screened_at_a_quarter_width_before_half(tmp_path):
    told = []
    result, report = export_verified(QUARTERED, tmp_path, {"mjcf"}, progress=told.append)
    split = [t for t in told if t.startswith("layering split plates")]
    assert split == ["layering split plates and brackets at the usual width",
                     "layering split plates and brackets at 0.25 of the usual width",
                     "layering split plates and brackets at 0.5 of the usual width"]  # fmt: skip
    usual = resolve_sizes(QUARTERED, assemble(QUARTERED).parts, None).link_width
    assert result.sizes["link_width"] == pytest.approx(usual / 4)  # half did not layer
    assert any("arm_of" in part for part in result.parts)
    assert report.passed, report.failed
