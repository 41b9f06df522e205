"""Export options (part sizes, material) and the defaults derived from a mechanism's own scale."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from linkd.mechanism import Mechanism

from .parts import Part


@dataclass
class ExportOptions:
    """Part sizes in the mechanism's units; None means derived from the mechanism's scale."""

    link_width: float | None = None  # plate width around the joints
    hole_diameter: float | None = None  # pin holes (pins have this diameter)
    thickness: float | None = None  # plate thickness
    layer_gap: float | None = None  # axial play between neighbouring layers
    clearance: float | None = None  # least in-plane gap between plates of one layer
    density: float = 1200.0  # kg/m^3 (PLA-like)
    # Where no flat layering builds, split plates and hold ground pins on brackets (`braced`),
    # or fork a part (`forked`).
    # Its search takes seconds to refuse a mechanism, so a design run past its time budget goes
    # without.
    brackets: bool = True


@dataclass(frozen=True)
class Sizes:
    """Resolved sizes, in the mechanism's units."""

    link_width: float
    hole_diameter: float
    thickness: float
    layer_gap: float
    clearance: float
    density: float

    @property
    def pitch(self) -> float:
        """Height of one layer: a plate and the gap above it."""
        return self.thickness + self.layer_gap

    def to_dict(self) -> dict:
        return asdict(self)


def resolve_sizes(mech: Mechanism, parts: list[Part], options: ExportOptions | None) -> Sizes:
    """Fill unset options from the mechanism: the width is 12% of its RMS radius, capped at 60%
    of the shortest joint spacing within a part (so neighbouring holes keep a wall between
    them); hole, thickness, gap and clearance are fixed fractions of the width."""
    options = options or ExportOptions()
    spacing = [
        np.linalg.norm(mech.positions[a] - mech.positions[b])
        for part in parts
        for k, a in enumerate(part.joints)
        for b in part.joints[k + 1 :]
    ]
    width = _given(
        options.link_width, min(0.12 * mech.scale, 0.6 * min(spacing, default=mech.scale))
    )
    sizes = Sizes(
        link_width=width,
        hole_diameter=_given(options.hole_diameter, 0.4 * width),
        thickness=_given(options.thickness, 0.4 * width),
        layer_gap=_given(options.layer_gap, 0.1 * width),
        clearance=_given(options.clearance, 0.2 * width),
        density=float(options.density),
    )
    for name, value in sizes.to_dict().items():
        if not 0 < value < np.inf:
            raise ValueError(
                f"the {name.replace('_', ' ')} must be a positive number, got {value:g}"
            )
    if not sizes.hole_diameter < sizes.link_width:
        raise ValueError(f"the hole diameter ({sizes.hole_diameter:g}) must be smaller than the "
                         f"link width ({sizes.link_width:g})")  # fmt: skip
    if spacing and not sizes.hole_diameter < min(spacing):  # the holes of a part would merge
        raise ValueError(f"the hole diameter ({sizes.hole_diameter:g}) must be smaller than the "
                         f"least spacing of two joints of a part ({min(spacing):g})")  # fmt: skip
    return sizes


def _given(value: float | None, default: float) -> float:
    return float(default if value is None else value)
