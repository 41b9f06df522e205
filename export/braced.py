"""Split cranks on a shaft held by a ground bracket: for mechanisms no flat layering builds.

In some mechanisms the parts at the crank cross each other's pins near their joints: typically
a ternary crank whose two couplers each sweep, in the crank's frame, a whole disc round their
joint, covering the other's pin and the ground pivot. Then no order of flat layers keeps every
pin clear, and neither narrower nor bent links change that. Three constructions together do:

- the crank is cut into arms, one plate per joint besides a shaft joint, all fixed on the pin
  at the shaft joint (the shaft), so each coupler can have an arm on its own side of the stack;
- the ground pivot is held by a bracket: a ground plate on a layer inside the stack with a hole
  for the pivot's pin, so that pin need not reach the base or the cover through the couplers;
- the bracket's arm runs straight out from the pivot to a post beyond everything the
  mechanism sweeps, which stands in the base plate (or hangs from the cover); the direction is
  the one whose arm the fewest pin paths and parts cross.

The split parts, the bracket and its post are layered like any other parts and pins: the
bracket is a static link from the pivot to the post, the post a pin of the ground at a point
that never moves, and the layer search keeps every part clear of them.
"""

from __future__ import annotations

import numpy as np

from .layers import Arm, Bracket, Layout, find_conflicts, stack_layers
from .options import Sizes
from .parts import CRANK, Assembly, Part, Pin

DIRECTIONS = 16  # directions tried for a bracket's arm
POST_MARGIN = 2.0  # link widths between the post and the farthest point the mechanism sweeps


def braced_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """Layers with the crank's ground pivot held by a bracket, the crank whole or cut into arms
    on a shaft at one of its pinned joints (whole first). ValueError when none layers."""
    crank = next(h for h in assembly.hinges if h.name == CRANK)
    pivot = crank.joint
    post = _post(assembly, paths, sizes, pivot)
    pinned = {pin.joint for pin in assembly.pins}
    shafts = [None, *(j for j in assembly.parts[crank.child].joints if j in pinned)]
    refusal = None
    for shaft in shafts:
        splits = {} if shaft is None else {crank.child: shaft}
        virtual, extended, owners = _virtual(assembly, paths, splits, pivot, post)
        try:
            layout = stack_layers(virtual, find_conflicts(virtual, extended, sizes), sizes)
        except ValueError as exc:
            refusal = refusal or exc
            continue
        return _real(assembly, layout, virtual, owners, post)
    raise refusal


def _post(assembly: Assembly, paths: np.ndarray, sizes: Sizes, pivot: int) -> np.ndarray:
    """Where the bracket's post stands: straight out from the pivot, past everything that moves,
    in the direction whose arm the fewest pin paths (then parts) come near."""
    centre = paths[pivot, 0]
    radius = np.linalg.norm(paths - centre, axis=-1).max() + POST_MARGIN * sizes.link_width
    angles = np.arange(DIRECTIONS) * (2 * np.pi / DIRECTIONS)
    posts = centre + radius * np.stack([np.cos(angles), np.sin(angles)], -1)
    n, first = len(paths), len(assembly.parts)
    arms = [Part(f"bracket{k}", "link", (pivot, n + k)) for k in range(DIRECTIONS)]
    still = np.repeat(posts[:, None], paths.shape[1], 1)
    trial = Assembly([*assembly.parts, *arms], [], assembly.pins, [])
    conflicts = find_conflicts(trial, np.concatenate([paths, still]), sizes)
    scores = [
        (sum(first + k in blocked for blocked in conflicts.blocked),
         int(conflicts.parts[first + k].sum()), k)
        for k in range(DIRECTIONS)
    ]  # fmt: skip
    return posts[min(scores)[2]]


def _virtual(
    assembly: Assembly, paths: np.ndarray, splits: dict[int, int], pivot: int, post: np.ndarray
) -> tuple[Assembly, np.ndarray, list[int]]:
    """The assembly the layer search sees: split parts as one link per arm, the bracket as a
    static link from the pivot to the post (a point appended to the paths), the pivot's pin
    held by the bracket instead of the ground, and the post as a pin of the ground. Returns it,
    the extended paths and the real part of every virtual one (the bracket's is -1)."""
    parts, owners = [assembly.parts[0]], [0]
    for p, part in enumerate(assembly.parts[1:], start=1):
        if p in splits:
            shaft = splits[p]
            arms = [Part(f"{part.name}_arm{j}", "link", (shaft, j)) for j in part.joints
                    if j != shaft]  # fmt: skip
            parts += arms
            owners += [p] * len(arms)
        else:
            parts.append(part)
            owners.append(p)
    point = len(paths)
    bracket = len(parts)
    parts.append(Part("ground_bracket", "link", (pivot, point)))
    owners.append(-1)
    pins = []
    for pin in assembly.pins:
        members = [q for q, part in enumerate(parts) if q and pin.joint in part.joints]
        if pin.joint != pivot and 0 in pin.members:
            members.insert(0, 0)
        pins.append(Pin(pin.name, pin.joint, members[0], tuple(members)))
    pins.append(Pin("post", point, 0, (0, bracket)))
    still = np.repeat(post[None, None], paths.shape[1], 1)
    return Assembly(parts, [], pins, []), np.concatenate([paths, still]), owners


def _real(
    assembly: Assembly, layout: Layout, virtual: Assembly, owners: list[int], post: np.ndarray
) -> Layout:
    """The layout of the real parts from the virtual one: a split part's layer is its lowest
    arm's, its arms listed with their layers; the bracket and where its post goes."""
    layers = np.zeros(len(assembly.parts), int)
    arms: dict[int, list[Arm]] = {}
    point = virtual.pins[-1].joint  # the post's
    for q, owner in enumerate(owners):
        joints, layer = virtual.parts[q].joints, int(layout.layers[q])
        if owner < 0:
            bracket = Bracket(joints[0], (float(post[0]), float(post[1])), layer,
                              point in layout.top_joints)  # fmt: skip
            continue
        if owner and virtual.parts[q].name != assembly.parts[owner].name:
            arms.setdefault(owner, []).append(Arm(joints, layer))
        layers[owner] = min(layers[owner] or layer, layer)
    top = tuple(j for j in layout.top_joints if j != point)
    return Layout(layers, layout.pin_spans[: len(assembly.pins)], top, layout.count,
                  layout.min_gap, layout.minimal, arms={p: tuple(a) for p, a in arms.items()},
                  brackets=(bracket,))  # fmt: skip
