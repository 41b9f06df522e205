"""Frame plates between modules: for mechanisms built of modules on one crank, as a
Strandbeest's leg pairs are.

Where the moving parts other than the crank fall into groups (modules) that meet only at the
ground's pivots and at the crank's pins, and nothing but the crank turns on the motor's pivot,
each module can be layered on its own, in a storey between two ground plates (base, frames
and cover), as a Strandbeest is built:

- the crank is cut into arms from the motor's pivot to each module's crank pins, two per
  module, one below every part of the module that passes over the pivot and one above them
  all (the top module has only the lower one); the crank pins are fixed in the arms, with the
  module's parts turning on them (a crankshaft);
- the motor's pin is cut into journals fixed in the crank: one from the base to the bottom
  module's lower arm, and one from each upper arm through the frame above it to the next
  module's lower arm, each turning in the ground plate it passes;
- a ground pivot's parts in a module turn on rods fixed in the frames: one from the frame
  below through the parts under those passing over the pivot, one from the frame above
  through the parts over them; the frames are held by posts from the base to the cover,
  beyond everything the mechanism sweeps.

Modules are taken joined at their crank pins, then apart there (a crank pin carrying several
modules is cut into a rod per module), and the fewer layers kept. No pin crosses a frame but
the journals and the ground's own rods and posts, so each module's layer search is that of a
small mechanism (`stacking`); a module with no layering on two arms goes on top, on one.
"""

from __future__ import annotations

import numpy as np

from .braced import POST_MARGIN
from .layers import Arm, Conflicts, Fork, Layout, find_conflicts, least_gap
from .options import Sizes
from .parts import Assembly, Part, Pin
from .stacking import PinState, fewest_layers, find_order, stack_in_order

POSTS = 3  # posts holding the frames, evenly round the motor's pivot


def framed_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers of the modules stacked between frames, the fewer of modules joined at their crank
    pins and modules apart there, each on its own arms (ValueError where the mechanism is not
    modules on one crank, or a module has no layering)."""
    found, refusal = [], None
    for apart in (False, True):
        try:
            found.append(_framed(assembly, paths, sizes, _modules(assembly, apart)))
        except ValueError as exc:
            refusal = refusal or exc
    if not found:
        raise refusal
    return min(found, key=lambda layout: layout.count)


def modular(assembly: Assembly) -> bool:
    """Whether the mechanism is made of modules on one crank (`framed_layers` applies)."""
    try:
        _modules(assembly, apart=True)  # modules joined at crank pins are modules apart there
    except ValueError:
        return False
    return True


def _framed(assembly: Assembly, paths: np.ndarray, sizes: Sizes, modules: tuple) -> Layout:
    """The layers of `modules` (`_modules`) between frames."""
    crank, motor = assembly.crank.child, assembly.crank.joint
    modules, arm_joints = modules
    union, index = _doubled(assembly, modules, arm_joints)
    conflicts = find_conflicts(union, paths, sizes)
    stacked = []  # each module with both arms, or why not
    for m, parts in enumerate(modules):
        try:
            stacked.append(_stack(union, conflicts, index, parts, m, motor, double=True))
        except ValueError as exc:
            stacked.append(exc)
    failed = [m for m, found in enumerate(stacked) if isinstance(found, ValueError)]
    if len(failed) > 1:
        raise stacked[failed[0]]
    last = failed[0] if failed else len(modules) - 1  # on one arm: no journal above it
    stacked[last] = _stack(union, conflicts, index, modules[last], last, motor, double=False)
    layers = np.zeros(len(union.parts), int)
    rods: dict[int, list] = {}  # pins cut per module: its parts there and the rod's span
    lows, highs, frames = [], [], [0]  # the base, each frame, and last the cover
    for m in [*(m for m in range(len(modules)) if m != last), last]:
        local, count = stacked[m]
        for q, layer in local.items():
            layers[q] = frames[-1] + layer
        ends = [int(layers[index[("arm", m, s)]]) for s in (0, 1)[: 1 + (m != last)]]
        lows.append(ends[0])
        highs += ends[1:]
        frames.append(frames[-1] + count + 1)
        for k, pin in enumerate(assembly.pins):
            mine = tuple(p for p in pin.members if p and index.get(("part", p)) in local)
            at = [int(layers[index[("part", p)]]) for p in mine]
            if mine and 0 in pin.members:  # on rods from the frames below and above
                passing = [int(layers[q]) for q in conflicts.blocked[k] if q in local]
                rods.setdefault(k, []).extend(_pivot_rods(mine, at, passing, *frames[-2:]))
            elif mine and crank in pin.members:  # on a crank pin between the module's arms
                rods.setdefault(k, []).append((mine, (min(*at, *ends), max(*at, *ends))))
    journals = zip([frames[0], *highs], lows)  # from the base, and through each frame
    motor_pin = next(k for k, pin in enumerate(assembly.pins) if pin.joint == motor)
    forks = {
        k: Fork(0 if 0 in assembly.pins[k].members else crank, tuple(spans))
        for k, spans in rods.items()
        if len(spans) > 1 or 0 in assembly.pins[k].members
    }
    forks[motor_pin] = Fork(crank, tuple(((0,), span) for span in journals))
    arms = tuple(Arm(joints, int(layers[index[("arm", m, s)]])) for m, joints in
                 enumerate(arm_joints) for s in (0, 1)[: 1 + (m != last)])  # fmt: skip
    real, spans = np.zeros(len(assembly.parts), int), []
    for p in range(1, len(assembly.parts)):
        real[p] = lows[0] if p == crank else layers[index[("part", p)]]
    for k, pin in enumerate(assembly.pins):
        if k in forks:
            spans.append((forks[k].rods[0][1][0], max(hi for _, (_, hi) in forks[k].rods)))
            continue
        at = [layer for p in pin.members for layer in _layers_at(layers, index, arms, p, pin.joint)]
        spans.append((min(at), max(at)))
    return Layout(real, spans, (), frames[-1] + 1, least_gap(conflicts, layers, sizes), False,
                  arms={crank: arms}, forks=forks, frames=tuple(frames[1:-1]),
                  frame_posts=posts_beyond(paths, motor, sizes))  # fmt: skip


def _modules(assembly: Assembly, apart: bool) -> tuple[list[list[int]], list[tuple[int, ...]]]:
    """The moving parts but the crank grouped into modules (parts sharing a joint that is not
    the ground's, nor with `apart` the crank's), and the crank's joints each module's arms
    join: the motor's pivot and the crank pins it hangs on (the first also the crank's joints
    no module uses). ValueError unless there are two or more and only the crank turns on the
    motor's pivot."""
    crank, motor = assembly.crank.child, assembly.crank.joint
    own = set(assembly.parts[crank].joints)
    shared = set(assembly.parts[0].joints) | (own if apart else {motor})
    rest = [p for p in range(1, len(assembly.parts)) if p != crank]
    if any(motor in assembly.parts[p].joints for p in rest):
        raise ValueError("not modules on one crank: another part turns on the motor's pivot")
    group = {p: p for p in rest}

    def root(p: int) -> int:
        while group[p] != p:
            p = group[p]
        return p

    for pin in assembly.pins:
        if pin.joint not in shared:
            mine = [p for p in pin.members if p in group]
            for p in mine[1:]:
                group[root(p)] = root(mine[0])
    modules: dict[int, list[int]] = {}
    for p in rest:
        modules.setdefault(root(p), []).append(p)
    if len(modules) < 2:
        raise ValueError("not modules on one crank: its parts are all joined to one another")
    used = [
        own & {j for p in parts for j in assembly.parts[p].joints} for parts in modules.values()
    ]
    if not all(used):
        raise ValueError("not modules on one crank: a group of parts does not reach the crank")
    used[0] |= own - set().union(*used)
    return list(modules.values()), [tuple(sorted(joints | {motor})) for joints in used]


def _doubled(
    assembly: Assembly, modules: list[list[int]], arm_joints: list[tuple[int, ...]]
) -> tuple[Assembly, dict[tuple, int]]:
    """The assembly as the layer search sees it: the crank replaced by two arms per module
    (the top module uses one), each joining the motor's pivot to the module's crank pins,
    fixed on them. Returns it and where each arm (("arm", module, 0 or 1)) and real part
    (("part", p)) went."""
    crank = assembly.crank.child
    parts, index = [assembly.parts[0]], {}
    for m, joints in enumerate(arm_joints):
        kind = "link" if len(joints) == 2 else "plate"
        for s in (0, 1):
            index[("arm", m, s)] = len(parts)
            parts.append(Part(f"{assembly.parts[crank].name}_arm{2 * m + s}", kind, joints))
    for p in sorted(q for group in modules for q in group):
        index[("part", p)] = len(parts)
        parts.append(assembly.parts[p])
    pins = []
    for pin in assembly.pins:
        members = [index[("part", p)] for p in pin.members if p not in (0, crank)]
        if crank in pin.members:
            members += [index[("arm", m, s)] for m, joints in enumerate(arm_joints)
                        if pin.joint in joints for s in (0, 1)]  # fmt: skip
        members = [0] * (0 in pin.members) + sorted(members)
        pins.append(Pin(pin.name, pin.joint, members[0], tuple(members)))
    return Assembly(parts, [], pins, []), index


def _stack(
    union: Assembly,
    conflicts: Conflicts,
    index: dict,
    parts: list[int],
    m: int,
    motor: int,
    double: bool,
) -> tuple[dict[int, int], int]:
    """One module's layers (1..count, by the union's part) with its arms, and the count. The
    lower arm stands on a journal from below and, `double`, the upper one hangs from one above,
    so every part passing over the motor's pivot lies between them (or over the one arm); a
    ground pivot's parts lie below or above every part passing over it, held from the frame on
    their side."""
    arms = [index[("arm", m, 0)], *[index[("arm", m, 1)]] * double]
    own = [*arms, *(index[("part", p)] for p in parts)]
    local = {q: k for k, q in enumerate(own)}
    motor_pin = next(k for k, pin in enumerate(union.pins) if pin.joint == motor)
    passing = [local[q] for q in conflicts.blocked[motor_pin] if q in local]
    pins = [([arm], passing) for arm in range(len(arms))]  # journals: from below, from above
    for pin, near in zip(union.pins, conflicts.blocked):
        members = [local[q] for q in pin.members if q in local]
        blocked = [local[q] for q in near if q in local]
        if pin.joint != motor and members and 0 in pin.members:
            pins.append((blocked, members))  # none of its parts between two passing it
        elif pin.joint != motor and len(members) >= 2:
            pins.append((members, blocked))
    conflict = conflicts.parts[np.ix_(own, own)]
    grounded, cover = set(range(len(arms))), set(range(1, len(arms)))
    state = PinState(len(own), pins, grounded, cover)
    order = find_order(state, conflict)
    if order is None:
        names = ", ".join(union.parts[q].name for q in own[len(arms) :])
        raise ValueError(f"the module of {names} has no layering between two frames")
    layers = fewest_layers(conflict, state, stack_in_order(conflict, order))
    return {q: layers[local[q]] for q in own}, max(layers)


def _pivot_rods(
    parts: tuple[int, ...], layers: list[int], passing: list[int], below: int, above: int
) -> list[tuple[tuple[int, ...], tuple[int, int]]]:
    """A ground pivot's rods in one module (its `parts` on `layers`): one from the frame below
    through the parts under those passing over the pivot (on `passing`), one from the frame
    above through the parts over them."""
    first = min(passing, default=above)
    low = [(p, layer) for p, layer in zip(parts, layers) if layer < first]
    high = [(p, layer) for p, layer in zip(parts, layers) if layer > first]
    rods = []
    if low:
        rods.append((tuple(p for p, _ in low), (below, max(layer for _, layer in low))))
    if high:
        rods.append((tuple(p for p, _ in high), (min(layer for _, layer in high), above)))
    return rods


def _layers_at(layers: np.ndarray, index: dict, arms: tuple, p: int, joint: int) -> list[int]:
    """The layers of part p's plates at `joint`: the crank's arms there, or the part's own."""
    if ("part", p) in index:
        return [int(layers[index[("part", p)]])]
    return [arm.layer for arm in arms if joint in arm.joints]


def posts_beyond(paths: np.ndarray, motor: int, sizes: Sizes) -> tuple[tuple[float, float], ...]:
    """POSTS points round the motor's pivot, as far beyond its farthest point swept by any
    joint as a bracket's post is (`braced.POST_MARGIN` link widths)."""
    centre = paths[motor, 0]
    reach = np.linalg.norm(paths - centre, axis=-1).max() + POST_MARGIN * sizes.link_width
    angles = np.pi / 2 + 2 * np.pi * np.arange(POSTS) / POSTS
    points = centre + reach * np.stack([np.cos(angles), np.sin(angles)], -1)
    return tuple((float(x), float(y)) for x, y in points)
