"""Why a mechanism has no flat layering, in terms a designer can act on: a few pins that no
order of layers keeps clear of the parts passing over them, and which parts those are."""

from __future__ import annotations

from dataclasses import replace

from .layers import Conflicts, NoFlatLayers, stack_layers
from .options import Sizes
from .parts import Assembly

MAX_PINS = 6  # pins whose passing parts a refusal looks for; past it, it names the pins alone
MAX_NAMED = 12  # passing parts a refusal names, over all its pins


def why_refused(assembly: Assembly, conflicts: Conflicts, sizes: Sizes) -> str:
    """Pins that alone cannot all be kept clear with whole, straight parts, each with the parts
    passing it that keep it so: "pin_1 (passed by link_2_3) and pin_4 (passed by ...)", or the
    pins alone where there are more than MAX_PINS of them or more than MAX_NAMED such parts;
    "" when the whole set layers. No pin and no named part can be left out: each is dropped in
    turn while the rest stay impossible. Layer searches of a few pins each: milliseconds."""
    blocked = dict(enumerate(conflicts.blocked))  # pin index -> the parts kept off it
    if not _impossible(assembly, conflicts, sizes, blocked):
        return ""
    for k in list(blocked):
        fewer = {p: parts for p, parts in blocked.items() if p != k}
        if _impossible(assembly, conflicts, sizes, fewer):
            blocked = fewer
    pins = {k: assembly.pins[k].name for k in blocked}
    if len(pins) > MAX_PINS:
        return _listed(list(pins.values()))
    for k in list(blocked):
        for q in list(blocked[k]):
            fewer = {**blocked, k: [r for r in blocked[k] if r != q]}
            if _impossible(assembly, conflicts, sizes, fewer):
                blocked = fewer
    if sum(map(len, blocked.values())) > MAX_NAMED:
        return _listed(list(pins.values()))
    named = [f"{pins[k]} (passed by {', '.join(assembly.parts[q].name for q in parts)})"
             if parts else pins[k] for k, parts in blocked.items()]  # fmt: skip
    return _listed(named)


def _impossible(
    assembly: Assembly, conflicts: Conflicts, sizes: Sizes, blocked: dict[int, list[int]]
) -> bool:
    """Does no stack keep the pins `blocked` (index -> the parts kept off it) clear?"""
    chosen = replace(assembly, pins=[assembly.pins[k] for k in blocked])
    try:
        stack_layers(chosen, replace(conflicts, blocked=list(blocked.values())), sizes,
                     fewest=False)  # fmt: skip
    except NoFlatLayers:
        return True
    return False


def _listed(names: list[str]) -> str:
    """Names as a list in words: "a", "a and b", "a, b and c"."""
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
