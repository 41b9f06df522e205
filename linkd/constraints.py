"""Designer's constraints: where the motor and the ground may go, the space the mechanism may
sweep, the shortest link, the most joints and the worst transmission angle it may have.

They are given in the curve's frame and units (contract §5) and parsed here from the command
line (`add_arguments`, `from_args`). `check` measures each one exactly on a final mechanism over
the full revolution: joint paths are traced at CHECK_ANGLES crank angles by the batched
kinematics, then again densely around every extreme found, so that what is reported is the
extreme itself, not a sample near it. `measure_batch` is the same measurement at sampled angles
for many candidates at once, which the design search screens with. Every measurement gives a
value and a margin: how far inside its limit the mechanism stays (in the curve's units, in
joints or in degrees); a constraint holds when its margin is not negative (up to rounding).
"""

from __future__ import annotations

import argparse
import math
import re
from dataclasses import dataclass, fields

import numpy as np

from linkd.batch import LinkageBatch
from linkd.errors import InputError
from linkd.geometry import Similarity
from linkd.kinematics import trace
from linkd.mechanism import Mechanism
from linkd.topology import assembly_plan
from linkd.validator import transmission_degrees

CHECK_ANGLES = 2048  # crank angles of the first pass of the exact check
REFINE_ANGLES = 65  # angles across the two sample intervals around each extreme found
SCREEN_ANGLES = 360  # crank angles of the batched screening
ROUNDING = 1e-9  # relative allowance for float rounding, times the mechanism's extent
MIN_JOINTS = 3  # the smallest linkage linkd designs: a point on the crank, tracing a circle


@dataclass(frozen=True)
class Box:
    """An axis-aligned rectangle x0 <= x <= x1, y0 <= y <= y1."""

    x0: float
    y0: float
    x1: float
    y1: float

    @property
    def size(self) -> tuple[float, float]:
        return self.x1 - self.x0, self.y1 - self.y0

    def margin(self, points: np.ndarray) -> np.ndarray:
        """Signed distance inside the box of points (..., 2), by the nearest side (< 0 outside)."""
        x, y = points[..., 0], points[..., 1]
        return np.minimum.reduce([x - self.x0, self.x1 - x, y - self.y0, self.y1 - y])

    def bounds_margin(self, bounds: np.ndarray) -> np.ndarray:
        """Margin of the rectangles bounds (..., 4) = x0, y0, x1, y1 inside this box."""
        sides = [bounds[..., 0] - self.x0, bounds[..., 1] - self.y0,
                 self.x1 - bounds[..., 2], self.y1 - bounds[..., 3]]  # fmt: skip
        return np.minimum.reduce(sides)

    def mapped(self, similarity: Similarity) -> Box:
        """The box moved by a similarity without rotation (as between a curve's frames)."""
        if not np.allclose(similarity.rotation, np.eye(2)):
            raise ValueError("only a translation and a scale keep a box axis-aligned")
        (x0, y0), (x1, y1) = similarity.apply(np.array([[self.x0, self.y0], [self.x1, self.y1]]))
        return Box(float(x0), float(y0), float(x1), float(y1))

    def to_list(self) -> list[float]:
        return [float(v) for v in (self.x0, self.y0, self.x1, self.y1)]


@dataclass(frozen=True)
class Constraints:
    """The constraints a designer gave; None where not given. Lengths in one frame's units."""

    motor_at: tuple[float, float] | None = None  # the crank pivot exactly here
    ground_box: Box | None = None  # every fixed joint inside
    envelope: Box | None = None  # every joint, at every crank angle, inside
    min_link: float | None = None  # every link at least this long
    max_joints: int | None = None  # at most this many joints
    min_transmission: float | None = None  # degrees: transmission angles within [d, 180 - d]

    def given(self) -> list[str]:
        return [f.name for f in fields(self) if getattr(self, f.name) is not None]

    def __bool__(self) -> bool:
        return bool(self.given())

    def mapped(self, similarity: Similarity) -> Constraints:
        """The same constraints in another frame: `similarity` maps this frame to that one."""
        motor = self.motor_at
        if motor is not None:
            motor = tuple(float(v) for v in similarity.apply(np.array(motor)))
        return Constraints(
            motor,
            self.ground_box.mapped(similarity) if self.ground_box else None,
            self.envelope.mapped(similarity) if self.envelope else None,
            self.min_link * similarity.scale if self.min_link is not None else None,
            self.max_joints,
            self.min_transmission,
        )

    def to_dict(self) -> dict:
        """The given constraints as JSON values (boxes and points as lists)."""
        out = {}
        for name in self.given():
            value = getattr(self, name)
            out[name] = value.to_list() if isinstance(value, Box) else value
        if "motor_at" in out:
            out["motor_at"] = [float(v) for v in out["motor_at"]]
        if "min_link" in out:
            out["min_link"] = float(out["min_link"])
        return out


# ---- the command line ---------------------------------------------------------------------

OPTIONS = {
    "motor_at": ("X,Y", "the crank pivot exactly at this point"),
    "ground_box": ("X0,Y0,X1,Y1", "every fixed joint inside this rectangle"),
    "envelope": ("X0,Y0,X1,Y1", "every joint inside this rectangle over the whole revolution"),
    "min_link": ("L", "every link at least this long"),
    "max_joints": ("N", "at most this many joints"),
    "min_transmission": ("DEG", "transmission angles within [DEG, 180 - DEG] over the revolution"),
}


def option(name: str) -> str:
    return "--" + name.replace("_", "-")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The constraint options, in the curve's (or the mechanism's) frame and units."""
    group = parser.add_argument_group("designer's constraints (in the curve's frame and units)")
    for name, (metavar, text) in OPTIONS.items():
        group.add_argument(option(name), dest=name, metavar=metavar, help=text)
    # Let values such as -5,3 follow an option: argparse only takes -5 or -.5 for a number.
    parser._negative_number_matcher = re.compile(r"^-\.?\d")


def from_args(args: argparse.Namespace) -> Constraints:
    """Parse the constraint options; a one-line InputError names what is wrong."""
    text = {name: getattr(args, name, None) for name in OPTIONS}
    motor = _numbers("motor_at", text["motor_at"], 2)
    ground = _box("ground_box", text["ground_box"])
    envelope = _box("envelope", text["envelope"])
    min_link = _numbers("min_link", text["min_link"], 1)
    if min_link is not None and not min_link[0] > 0:
        raise InputError(f"--min-link must be a positive length, got {text['min_link']}")
    joints = text["max_joints"]
    if joints is not None:
        if not re.fullmatch(r"\s*\+?\d+\s*", joints):
            raise InputError(f"--max-joints: expected a whole number, got {joints!r}")
        if int(joints) < MIN_JOINTS:
            smallest = "the smallest linkage linkd designs: a point on the crank"
            raise InputError(f"--max-joints must be at least {MIN_JOINTS} ({smallest}), "
                             f"got {int(joints)}")  # fmt: skip
    angle = _numbers("min_transmission", text["min_transmission"], 1)
    if angle is not None and not 0 <= angle[0] < 90:
        raise InputError(
            f"--min-transmission must be at least 0 and below 90 degrees, got {angle[0]:g}"
        )
    if motor is not None:
        for name, box in (("ground box", ground), ("envelope", envelope)):
            if box is not None and box.margin(np.array(motor)) < 0:
                raise InputError(f"--motor-at {motor[0]:g},{motor[1]:g} is outside the {name}")
    if ground is not None and envelope is not None and not _overlap(ground, envelope):
        raise InputError("--ground-box and --envelope do not overlap: no fixed joint fits")
    return Constraints(
        motor,
        ground,
        envelope,
        None if min_link is None else min_link[0],
        None if joints is None else int(joints),
        None if angle is None else angle[0],
    )


def _overlap(a: Box, b: Box) -> bool:
    return max(a.x0, b.x0) <= min(a.x1, b.x1) and max(a.y0, b.y0) <= min(a.y1, b.y1)


def _numbers(name: str, text: str | None, count: int) -> tuple | None:
    if text is None:
        return None
    parts = text.split(",")
    shape = {1: "a number", 2: "X,Y", 4: "X0,Y0,X1,Y1"}[count]
    try:
        values = tuple(float(p) for p in parts if "_" not in p)
    except ValueError:
        values = ()
    if len(values) != count or len(parts) != count or not all(map(math.isfinite, values)):
        raise InputError(f"{option(name)}: expected {shape} (finite numbers), got {text!r}")
    return values


def _box(name: str, text: str | None) -> Box | None:
    values = _numbers(name, text, 4)
    if values is None:
        return None
    box = Box(*values)
    if not (box.x1 > box.x0 and box.y1 > box.y0):
        raise InputError(f"{option(name)}: expected X0,Y0,X1,Y1 with X1 > X0 and Y1 > Y0, "
                         f"got {text!r}")  # fmt: skip
    return box


# ---- measuring ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Measured:
    """One constraint measured on one mechanism."""

    name: str
    limit: object  # as given
    value: object  # what the mechanism has (see `measure_batch`)
    margin: float  # how far inside the limit it stays; negative: by how much it is violated
    holds: bool

    def to_dict(self) -> dict:
        return {"name": self.name, "option": option(self.name), "limit": self.limit,
                "value": self.value, "margin": self.margin, "holds": self.holds}  # fmt: skip


def measure_batch(
    batch: LinkageBatch, c: Constraints, angles: int = SCREEN_ANGLES
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each given constraint's (values, margins) for every linkage of `batch` (in the frame of
    `c`), at `angles` crank angles. Values: the crank pivot (B, 2); the bounds x0, y0, x1, y1
    of the fixed joints (B, 4) and of all joints over the revolution (B, 4); the shortest link
    (B,); the joint count (B,); the worst transmission angle in degrees (B,)."""
    motion = None
    if c.envelope is not None or c.min_transmission is not None:
        plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
        motion = trace(batch.positions, plan, angles)
    return _measure(batch, c, motion)


def _measure(batch: LinkageBatch, c: Constraints, motion) -> dict:
    out = {}
    valid, fixed, pos = batch.valid, batch.fixed & batch.valid, batch.positions
    if c.motor_at is not None:
        pivot = pos[:, 0]
        out["motor_at"] = (pivot, -np.linalg.norm(pivot - np.array(c.motor_at), axis=1))
    if c.ground_box is not None:
        bounds = _bounds(pos, pos, fixed)
        out["ground_box"] = (bounds, c.ground_box.bounds_margin(bounds))
    if c.envelope is not None:
        low = np.stack([motion.x.min(2), motion.y.min(2)], -1)  # (B, N, 2) over the turn
        high = np.stack([motion.x.max(2), motion.y.max(2)], -1)
        bounds = _bounds(low, high, valid)
        out["envelope"] = (bounds, c.envelope.bounds_margin(bounds))
    if c.min_link is not None:
        d = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1)
        shortest = np.where(np.triu(batch.adjacency & valid[:, None] & valid[:, :, None], 1),
                            d, np.inf).min((1, 2))  # fmt: skip
        out["min_link"] = (shortest, shortest - c.min_link)
    if c.max_joints is not None:
        joints = valid.sum(1)
        out["max_joints"] = (joints, (c.max_joints - joints).astype(float))
    if c.min_transmission is not None:
        worst = transmission_degrees(np.asarray(motion.margin, dtype=np.float64))
        out["min_transmission"] = (worst, worst - c.min_transmission)
    return out


def _bounds(low: np.ndarray, high: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(B, 4) x0, y0, x1, y1 of the joints where mask (B, N), each reaching from `low` to
    `high` (B, N, 2). The envelope passes each joint's extremes over the turn, reduced along
    the paths' contiguous axis: masking every point of every path took most of a screen."""
    low = np.where(mask[..., None], low, np.inf).min(1)
    high = np.where(mask[..., None], high, -np.inf).max(1)
    return np.concatenate([low, high], 1)


def check(mech: Mechanism, c: Constraints) -> list[Measured]:
    """Every given constraint measured exactly on `mech` (in the frame and units of `c`)."""
    batch = LinkageBatch.from_mechanisms([mech])
    motion = None
    if c.envelope is not None or c.min_transmission is not None:
        motion = _extremes(batch)
    measured = _measure(batch, c, motion)
    extent = max(np.ptp(mech.positions, axis=0).max(), 1e-300)
    out = []
    for name in c.given():
        value, margin = (v[0] for v in measured[name])
        tolerance = ROUNDING * extent if name in ("motor_at", "ground_box", "envelope") else 0.0
        limit = getattr(c, name)
        limit = limit.to_list() if isinstance(limit, Box) else limit
        limit = list(limit) if isinstance(limit, tuple) else limit
        plain = value.tolist() if isinstance(value, np.ndarray) else value
        plain = int(plain) if name == "max_joints" else plain
        out.append(Measured(name, limit, plain, float(margin), bool(margin >= -tolerance)))
    return out


class _Motion:
    """Joint paths and worst transmission gathered from several traces of one mechanism."""

    def __init__(self, x: np.ndarray, y: np.ndarray, margin: np.ndarray):
        self.x, self.y, self.margin = x, y, margin


def _extremes(batch: LinkageBatch) -> _Motion:
    """Paths of one mechanism at CHECK_ANGLES angles plus dense angles around each extreme:
    the extreme x and y of the joints (the three joints nearest each side) and each dyad's
    smallest transmission sine. Sampling two intervals around a sampled extreme at
    REFINE_ANGLES angles brings it within about 1e-7 of the mechanism's size of the true one."""
    plan = assembly_plan(batch.adjacency, batch.fixed, batch.valid)
    coarse = trace(batch.positions, plan, CHECK_ANGLES, full=True)
    step = 2 * np.pi / CHECK_ANGLES
    x, y = coarse.x[0][batch.valid[0]], coarse.y[0][batch.valid[0]]  # (N, T)
    centres = []
    for values in (x, -x, y, -y):
        top = np.argsort(values.max(1))[-3:]
        centres += list(values[top].argmax(1))
    if coarse.sin2 is not None:
        centres += list(coarse.sin2[0].argmin(1))
    offsets = np.linspace(-step, step, REFINE_ANGLES)
    fine = (np.array(centres)[:, None] * step + offsets).reshape(-1)
    dense = trace(batch.positions, plan, fine % (2 * np.pi))
    return _Motion(
        np.concatenate([coarse.x, dense.x], 2),
        np.concatenate([coarse.y, dense.y], 2),
        np.minimum(coarse.margin, dense.margin),
    )


# ---- words --------------------------------------------------------------------------------


def describe(m: Measured, units: str) -> str:
    """What a violated constraint means, on one line (without the verdict)."""
    if m.name == "motor_at":
        return f"the crank pivot is {-m.margin:.4g} {units} from the motor point"
    if m.name == "ground_box":
        return f"a fixed joint is {-m.margin:.4g} {units} outside the ground box"
    if m.name == "envelope":
        x0, y0, x1, y1 = m.value
        return (f"the joints sweep {x1 - x0:.4g} x {y1 - y0:.4g} {units} and reach "
                f"{-m.margin:.4g} {units} outside the envelope")  # fmt: skip
    if m.name == "min_link":
        return f"the shortest link is {m.value:.4g} {units}, below {m.limit:g}"
    if m.name == "max_joints":
        return f"it has {m.value} joints, more than {m.limit}"
    return f"its worst transmission angle is {m.value:.1f} deg, below {m.limit:g}"


def summary(measured: list[dict], units: str) -> str:
    """The report's constraint entries, each with its margin, as one line."""
    parts = []
    for m in measured:
        if m["name"] == "motor_at":
            parts.append("crank pivot on the motor point")
        elif m["name"] == "max_joints":
            parts.append(f"{m['value']} of at most {m['limit']} joints")
        elif m["name"] == "min_transmission":
            parts.append(f"transmission {m['value']:.1f} >= {m['limit']:g} deg")
        elif m["name"] == "min_link":
            parts.append(f"shortest link {m['value']:.4g} >= {m['limit']:g} {units}")
        else:
            where = "ground box" if m["name"] == "ground_box" else "envelope"
            parts.append(f"{m['margin']:.4g} {units} inside the {where}")
    return ", ".join(parts)


NO_DESIGN = {
    "motor_at": "no design puts its crank pivot on the motor point",
    "ground_box": "no design keeps every fixed joint inside the ground box",
    "envelope": "no design keeps every joint inside the envelope",
    "min_link": "no design has every link at least {limit:g} {units} long",
    "max_joints": "no design has at most {limit} joints",
    "min_transmission": "no design keeps every transmission angle within "
    "[{limit:g}, {other:g}] deg",
}


def no_design(m: Measured, units: str) -> str:
    """'no design ...' naming the constraint `m` is a measurement of."""
    other = 180 - m.limit if m.name == "min_transmission" else 0
    return NO_DESIGN[m.name].format(limit=m.limit, units=units, other=other)


def binding(measured: dict[str, tuple[np.ndarray, np.ndarray]], c: Constraints, units: str) -> str:
    """One line naming the constraint that ruled out the most candidates, and how near the
    candidate that came closest to meeting it got."""
    counts = {name: int((margin < 0).sum()) for name, (_, margin) in measured.items()}
    name = max(counts, key=counts.get)
    values, margins = measured[name]
    best = int(np.argmax(margins))
    value = values[best].tolist() if isinstance(values[best], np.ndarray) else values[best]
    m = Measured(name, getattr(c, name), value, float(margins[best]), False)
    return f"{no_design(m, units)}; in the best, {describe(m, units)}"
