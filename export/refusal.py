"""Why a mechanism has no flat layering, in terms a designer can act on: a few pins that no
order of layers keeps clear of the parts passing over them."""

from __future__ import annotations

from dataclasses import replace

from .layers import Conflicts, NoFlatLayers, stack_layers
from .options import Sizes
from .parts import Assembly


def blocking_pins(assembly: Assembly, conflicts: Conflicts, sizes: Sizes) -> list[str]:
    """Names of a set of pins that alone cannot all be kept clear with whole, straight parts,
    none of which can be left out (each is dropped in turn while the rest stay proved
    impossible); empty when the whole set is not proved impossible. Layer searches of a few
    pins each: milliseconds to a few seconds."""
    keep = list(range(len(assembly.pins)))
    if not _impossible(assembly, conflicts, sizes, keep):
        return []
    for k in list(keep):
        fewer = [p for p in keep if p != k]
        if _impossible(assembly, conflicts, sizes, fewer):
            keep = fewer
    return [assembly.pins[k].name for k in keep]


def _impossible(assembly: Assembly, conflicts: Conflicts, sizes: Sizes, pins: list[int]) -> bool:
    chosen = replace(assembly, pins=[assembly.pins[k] for k in pins])
    blocked = [conflicts.blocked[k] for k in pins]
    try:
        stack_layers(chosen, replace(conflicts, blocked=blocked), sizes)
    except NoFlatLayers as exc:
        return exc.proved
    return False
