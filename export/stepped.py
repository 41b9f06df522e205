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


def cuts(length: float, width: float) -> tuple[float, ...]:
    """Where a link of `length` may step, as fractions of the way from its first joint: a link
    width from each end (a short link: its middle). A step that near a joint lets the link leave
    its pin's layers at once, as a pin stopping at the plates it joins would."""
    near = width / length
    return (0.5,) if near >= 1 / 3 else (near, 1 - near)


def split_links(
    assembly: Assembly, paths: np.ndarray, width: float
) -> tuple[Assembly, np.ndarray, list[int], dict[int, tuple[float, ...]]]:
    """The assembly with every binary link cut into pieces at its `cuts`, each cut an extra
    joint (index N + k) held by a spacer pin; the paths with those cuts appended; the part of
    every piece; and the cuts of every link."""
    n = len(paths)
    pieces: list[Part] = []
    owner: list[int] = []
    piece_at: dict[tuple[int, int], int] = {}  # (part, joint) -> piece
    extra, spacers, where = [], [], {}
    for p, part in enumerate(assembly.parts):
        if part.kind != "link":
            piece_at.update({(p, j): len(pieces) for j in part.joints})
            pieces.append(part)
            owner.append(p)
            continue
        a, b = part.joints
        where[p] = cuts(float(np.linalg.norm(paths[a, 0] - paths[b, 0])), width)
        ends = [a]
        for f in where[p]:
            ends.append(n + len(extra))
            extra.append((1 - f) * paths[a] + f * paths[b])
        ends.append(b)
        first = len(pieces)
        for k in range(len(ends) - 1):
            pieces.append(Part(f"{part.name}_piece{k}", "piece", (ends[k], ends[k + 1])))
            owner.append(p)
        for k, cut in enumerate(ends[1:-1]):
            members = (first + k, first + k + 1)
            spacers.append(Pin(f"{part.name}_spacer{k}", cut, members[0], members))
        piece_at[(p, a)], piece_at[(p, b)] = first, len(pieces) - 1
    pins = [
        Pin(pin.name, pin.joint, piece_at[(pin.hub, pin.joint)],
            tuple(piece_at[(m, pin.joint)] for m in pin.members))
        for pin in assembly.pins
    ]  # fmt: skip
    split = Assembly(pieces, [], pins + spacers, [])
    extended = np.concatenate([paths, np.array(extra).reshape(-1, *paths.shape[1:])])
    return split, extended, owner, where


def _runs(bounds: list[float], levels: np.ndarray) -> tuple[tuple[float, float, int], ...]:
    """Consecutive pieces on one layer merged: (from, to, layer) along the link."""
    runs: list[tuple[float, float, int]] = []
    for k, level in enumerate(levels.tolist()):
        if runs and runs[-1][2] == level:
            runs[-1] = (runs[-1][0], bounds[k + 1], level)
        else:
            runs.append((bounds[k], bounds[k + 1], level))
    return tuple(runs)


def stepped_layers(assembly: Assembly, paths: np.ndarray, sizes: Sizes) -> Layout:
    """A layout where links may step between layers (ValueError if even that cannot be built)."""
    split, extended, owner, where = split_links(assembly, paths, sizes.link_width)
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
    pairs = [(m[0], m[1]) for m, _ in pins[n_real:]]
    found = solve_exact(ExactProblem(conflict[1:, 1:], pins, grounded, pairs))
    if found is None:
        raise ValueError(
            "cannot be built even with stepped links: some parts pass over pins whose plates "
            "lie above and below them in every arrangement"
        )
    levels = np.array([0, *found.layers])
    layers = np.zeros(len(assembly.parts), dtype=int)
    steps = {}
    for piece, p in enumerate(owner):
        if piece and not layers[p]:
            layers[p] = levels[piece]
    for p, fractions in where.items():
        first = owner.index(p)
        runs = _runs([0.0, *fractions, 1.0], levels[first : first + len(fractions) + 1])
        if len(runs) > 1:
            steps[p] = runs
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
