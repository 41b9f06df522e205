"""Stepped links: layers for mechanisms that flat plates cannot build.

Some mechanisms have no flat layering: a part passes over a pin whose plates must lie above and
below it, in every order. Builders then crank a link: its two halves lie on different layers,
joined at the middle of the link by a spacer (a standoff as wide as the link, bonded or screwed
to both halves). Each half only has to keep clear of what passes near its own end, and the
spacer of what passes near the link's middle, so the stack has far more freedom.

Here every binary link is split into its two halves (pieces on their own), each plate and the
ground stay whole; the spacer is a pin joining the two halves, a link width across. The exact
search (`exact`) then gives every piece a layer, keeping halves together unless that costs a
layer or is impossible: a link whose halves share a layer is an ordinary flat link.
"""

from __future__ import annotations

import numpy as np

from .exact import ExactProblem, solve_exact
from .layers import Layout, find_conflicts
from .options import Sizes
from .parts import Assembly, Part, Pin


def split_links(
    assembly: Assembly, paths: np.ndarray, kinds: tuple[str, ...] = ("link",)
) -> tuple[Assembly, np.ndarray, list[int]]:
    """The assembly with every binary link split in two halves at its middle, which becomes an
    extra joint (index N + k) held by a spacer pin; the paths with those middles appended; and
    the part of every piece."""
    n = len(paths)
    pieces: list[Part] = []
    owner: list[int] = []
    piece_at: dict[tuple[int, int], int] = {}  # (part, joint) -> piece
    middles, spacers = [], []
    for p, part in enumerate(assembly.parts):
        if part.kind not in kinds:
            piece_at.update({(p, j): len(pieces) for j in part.joints})
            pieces.append(part)
            owner.append(p)
            continue
        middle = n + len(middles)
        middles.append(_step_point(assembly, paths, p))
        halves = []
        for j in part.joints:
            piece_at[(p, j)] = len(pieces)
            halves.append(len(pieces))
            pieces.append(Part(f"{part.name}_at_{j}", "half", (j, middle)))
            owner.append(p)
        spacers.append(Pin(f"{part.name}_spacer", middle, halves[0], tuple(halves)))
    pins = [
        Pin(pin.name, pin.joint, piece_at[(pin.hub, pin.joint)],
            tuple(piece_at[(m, pin.joint)] for m in pin.members))  # fmt: skip
        for pin in assembly.pins
    ]
    split = Assembly(pieces, [], pins + spacers, [])
    extended = np.concatenate([paths, np.array(middles).reshape(-1, *paths.shape[1:])])
    return split, extended, owner


STEP_AT = np.linspace(0.15, 0.85, 15)  # candidate places of a link's step, along it


def _step_point(assembly: Assembly, paths: np.ndarray, part: int) -> np.ndarray:
    """(T, 2) path of the place along a link where its step goes: the candidate that the
    fewest other parts come near (then the one they stay farthest from)."""
    from .layers import hull_edges, _point_segment

    a, b = assembly.parts[part].joints
    edges = [e for e in hull_edges(assembly, paths[:, 0]) if e[0] not in (0, part)]
    if not edges:
        return (paths[a] + paths[b]) / 2
    points = paths[..., 0] + 1j * paths[..., 1]
    owner = np.array([e[0] for e in edges])
    start, end = points[[e[1] for e in edges]], points[[e[2] for e in edges]]
    best, choice = None, (paths[a] + paths[b]) / 2
    for f in STEP_AT:
        at = (1 - f) * points[a] + f * points[b]
        gap = _point_segment(at, start, end).min(-1)  # per edge
        per_part = np.full(owner.max() + 1, np.inf)
        np.minimum.at(per_part, owner, gap)
        per_part = per_part[np.isfinite(per_part)]
        key = (np.sort(per_part)[:3].tolist())
        if best is None or key > best:
            best, choice = key, np.stack([at.real, at.imag], -1)
    return choice


def stepped_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes, kinds=("link",)) -> Layout:
    """A layout where links may step between layers (ValueError if even that cannot be built)."""
    split, extended, owner = split_links(assembly, paths, kinds)
    n_real = len(assembly.pins)
    wide = frozenset(range(n_real, len(split.pins)))
    conflicts = find_conflicts(split, extended, sizes, wide)
    owner_arr = np.array(owner)
    same_part = owner_arr[:, None] == owner_arr[None, :]
    conflict = conflicts.parts & ~same_part
    pins, grounded = [], set()
    for k, (pin, blocked) in enumerate(zip(split.pins, conflicts.blocked)):
        mine = {owner[m] for m in pin.members}
        members = [m - 1 for m in pin.members if m]
        pins.append((members, [q - 1 for q in blocked if owner[q] not in mine]))
        if k < n_real and 0 in pin.members:
            grounded.add(k)
    pairs = [(m[0], other) for m, _ in pins[n_real:] for other in m[1:]]
    found = solve_exact(ExactProblem(conflict[1:, 1:], pins, grounded, pairs))
    if found is None:
        raise ValueError(
            "cannot be built even with stepped links: some parts pass over pins whose plates "
            "lie above and below them in every arrangement"
        )
    levels = np.array([0, *found.layers])
    layers = np.zeros(len(assembly.parts), dtype=int)
    steps: dict[int, tuple[int, int]] = {}
    for piece, p in enumerate(owner):
        if piece and not layers[p]:
            layers[p] = levels[piece]
    for p, part in enumerate(assembly.parts):
        if part.kind == "link":
            ends = tuple(int(levels[owner.index(p) + k]) for k in range(2))
            if ends[0] != ends[1]:
                steps[p] = ends
    spans = []
    top = found.stack + 1
    for k, pin in enumerate(split.pins[:n_real]):
        span = [int(levels[m]) for m in pin.members if m]
        if 0 in pin.members:
            span.append(top if k in found.cover else 0)
        spans.append((min(span), max(span)))
    same = (levels[:, None] == levels[None, :]) & ~same_part
    same[0], same[:, 0] = False, False
    gap = (conflicts.distance[same] - sizes.link_width).min(initial=np.inf)
    cover = tuple(sorted(split.pins[k].joint for k in found.cover))
    return Layout(layers, spans, cover, found.stack + 1 + bool(cover), float(gap), found.minimal,
                  steps)  # fmt: skip
