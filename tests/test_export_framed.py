"""Frames between modules (linkd.export.framed) against the straps: where both build a
mechanism, the one with fewer layers is kept, the straps never with narrower parts than the
frames' (the walkers themselves: tests/test_walkers.py)."""

from linkd.classic import jansen_walker
from linkd.export import export_mechanism
from linkd.export.framed import framed_layers, modular
from linkd.export.layers import sweep
from linkd.export.options import resolve_sizes
from linkd.export.parts import assemble
from linkd.export.strapped import strapped_layers
from linkd.mechanism import Mechanism

# Generated (7 to 13 joints, seed 2026, no. 10 of 300): a crank plate with two crank pins, a
# module on each; neither straight nor bent links layer it.
TWO_MODULES = Mechanism(
    [(-95.015, -1.069), (-90.163, -18.59), (9.571, 45.935), (14.675, 20.028), (49.964, -16.962),
     (-87.555, 9.339), (-51.866, -21.995), (-34.527, -48.89), (-64.017, -52.717)],
    [1, 0, 0, 1, 0, 1, 0, 0, 0],
    [(0, 1), (0, 2), (1, 2), (1, 4), (2, 6), (2, 7), (3, 4), (5, 6), (6, 7), (6, 8), (7, 8)],
    (0, 1), 8,
)  # fmt: skip


def test_frames_give_way_to_straps_with_fewer_layers(tmp_path):
    assembly = assemble(TWO_MODULES)
    sizes = resolve_sizes(TWO_MODULES, assembly.parts, None)
    paths = sweep(TWO_MODULES, sizes.link_width)
    assert modular(assembly)
    strapped = strapped_layers(assembly, paths, sizes)
    assert strapped.count < framed_layers(assembly, paths, sizes).count
    result = export_mechanism(TWO_MODULES, tmp_path, {"mjcf"})
    assert result.layers == strapped.count
    assert any(part["kind"] == "sheave" for part in result.parts)
    assert not any("_frame" in part["name"] for part in result.parts)


def test_straps_are_not_tried_narrower_than_the_frames(tmp_path):
    tried = []
    result = export_mechanism(jansen_walker(3, mirrored=False), tmp_path, {"mjcf"},
                              progress=tried.append)  # fmt: skip
    assert any(part["name"].startswith("ground_frame") for part in result.parts)
    assert result.narrowed == 1.0
    straps = [step for step in tried if "eccentric straps" in step]
    assert straps == ["layering eccentric straps at the usual width"]
