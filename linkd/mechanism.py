"""The `Mechanism` type and its `mechanism.json` file (format `linkd-mechanism/1`).

A mechanism is a set of revolute joints (some pinned to ground), rigid links between pairs of
joints, a motor crank `pivot -> tip` that turns counter-clockwise, and an end-effector joint.
Positions are the assembly pose (crank angle 0) in the user's frame and units.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from linkd.errors import InputError
from linkd.geometry import Similarity

FORMAT = "linkd-mechanism/1"
UNITS_IN_METRES = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
DEFAULT_UNITS = "mm"


@dataclass(frozen=True, eq=False)
class Mechanism:
    """A planar one-degree-of-freedom linkage in its assembly pose."""

    positions: np.ndarray  # (N, 2) float64
    fixed: np.ndarray  # (N,) bool
    links: tuple[tuple[int, int], ...]  # undirected pairs, stored as (i, j) with i < j, sorted
    motor: tuple[int, int]  # (pivot, tip)
    end_effector: int
    units: str = DEFAULT_UNITS
    extra: dict[str, Any] = field(default_factory=dict)  # extra JSON keys, kept on save
    # [a, b]: the end effector traces the designed open path while the crank turns from a to b
    # (radians from the assembly pose); None: the designed path is the whole revolution.
    crank_range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        pos = np.array(self.positions, dtype=np.float64).reshape(-1, 2)
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "fixed", np.array(self.fixed, dtype=bool).reshape(-1))
        links = tuple(sorted((min(i, j), max(i, j)) for i, j in self.links))
        object.__setattr__(self, "links", tuple((int(i), int(j)) for i, j in links))
        object.__setattr__(self, "motor", (int(self.motor[0]), int(self.motor[1])))
        object.__setattr__(self, "end_effector", int(self.end_effector))
        if self.crank_range is not None:
            problem = crank_range_problem(self.crank_range)
            if problem:
                raise ValueError(f"crank_range {problem}")
            a, b = (float(v) for v in self.crank_range)
            object.__setattr__(self, "crank_range", (a, b))

    @property
    def n_nodes(self) -> int:
        return len(self.positions)

    @property
    def scale(self) -> float:
        """RMS distance of the joints from their centroid: the mechanism's size."""
        centred = self.positions - self.positions.mean(axis=0)
        return float(np.sqrt((centred**2).sum(axis=1).mean()))

    def adjacency(self) -> np.ndarray:
        """Symmetric boolean (N, N) link matrix."""
        a = np.zeros((self.n_nodes, self.n_nodes), dtype=bool)
        for i, j in self.links:
            a[i, j] = a[j, i] = True
        return a

    def link_lengths(self) -> np.ndarray:
        idx = np.array(self.links, dtype=int).reshape(-1, 2)
        return np.linalg.norm(self.positions[idx[:, 0]] - self.positions[idx[:, 1]], axis=1)

    def replace(self, **changes: Any) -> Mechanism:
        fields = {
            "positions": self.positions,
            "fixed": self.fixed,
            "links": self.links,
            "motor": self.motor,
            "end_effector": self.end_effector,
            "units": self.units,
            "extra": self.extra,
            "crank_range": self.crank_range,
        }
        fields.update(changes)
        return Mechanism(**fields)

    def transformed(self, similarity: Similarity) -> Mechanism:
        """The same mechanism moved by a similarity (a reflection reverses its path's direction:
        the crank range becomes the mirrored angles, traced backwards)."""
        moved = self.replace(positions=similarity.apply(self.positions))
        if self.crank_range is None or not similarity.reflects:
            return moved
        a, b = self.crank_range
        start = (-b) % (2 * math.pi)
        return moved.replace(crank_range=(start, start + (b - a)))

    def relabelled(self, order: np.ndarray | list[int]) -> Mechanism:
        """The same mechanism with node `order[k]` becoming node k."""
        order = np.asarray(order, dtype=int)
        new_index = np.empty_like(order)
        new_index[order] = np.arange(len(order))
        return self.replace(
            positions=self.positions[order],
            fixed=self.fixed[order],
            links=tuple((int(new_index[i]), int(new_index[j])) for i, j in self.links),
            motor=(int(new_index[self.motor[0]]), int(new_index[self.motor[1]])),
            end_effector=int(new_index[self.end_effector]),
        )

    # ---- mechanism.json -------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "units": self.units,
            "nodes": [
                {"x": float(x), "y": float(y), "fixed": bool(f)}
                for (x, y), f in zip(self.positions, self.fixed)
            ],
            "links": [[i, j] for i, j in self.links],
            "motor": list(self.motor),
            "end_effector": self.end_effector,
            **({"crank_range": list(self.crank_range)} if self.crank_range is not None else {}),
            **self.extra,
        }

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> Mechanism:
        path = Path(path)
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: cannot read mechanism file ({_reason(exc)})") from None
        try:
            data = json.loads(text, parse_constant=_reject_constant)
        except (json.JSONDecodeError, ValueError) as exc:
            raise InputError(f"{path}: not valid JSON ({_reason(exc)})") from None
        return cls.from_dict(data, source=str(path))

    @classmethod
    def from_dict(cls, data: Any, source: str = "mechanism") -> Mechanism:
        """Parse the contract's JSON object, refusing malformed content with an InputError."""

        def fail(message: str) -> InputError:
            return InputError(f"{source}: {message}")

        if not isinstance(data, dict):
            raise fail("top level must be a JSON object")
        fmt = data.get("format")
        if fmt != FORMAT:
            raise fail(f"'format' must be {FORMAT!r}, got {fmt!r}")
        units = data.get("units", DEFAULT_UNITS)
        if units not in UNITS_IN_METRES:
            raise fail(f"'units' must be one of {', '.join(UNITS_IN_METRES)}, got {units!r}")
        nodes = data.get("nodes")
        if not isinstance(nodes, list) or len(nodes) < 2:
            raise fail("'nodes' must be a list of at least 2 joints")
        positions, fixed = [], []
        for k, node in enumerate(nodes):
            if not isinstance(node, dict):
                raise fail(f"nodes[{k}] must be an object with x, y, fixed")
            for key in ("x", "y"):
                value = node.get(key)
                if not _is_number(value) or not math.isfinite(value):
                    raise fail(f"nodes[{k}].{key} must be a finite number, got {value!r}")
            if not isinstance(node.get("fixed", False), bool):
                raise fail(f"nodes[{k}].fixed must be true or false")
            positions.append((float(node["x"]), float(node["y"])))
            fixed.append(node.get("fixed", False))
        n = len(nodes)
        links = data.get("links")
        if not isinstance(links, list):
            raise fail("'links' must be a list of [i, j] pairs")
        seen = set()
        for k, link in enumerate(links):
            pair = _index_pair(link, n)
            if pair is None:
                raise fail(
                    f"links[{k}] must be a pair of joint indices in 0..{n - 1}, got {link!r}"
                )
            if pair[0] == pair[1]:
                raise fail(f"links[{k}] joins joint {pair[0]} to itself")
            key = (min(pair), max(pair))
            if key in seen:
                raise fail(f"links[{k}] duplicates link {list(key)}")
            seen.add(key)
        motor = _index_pair(data.get("motor"), n)
        if motor is None or motor[0] == motor[1]:
            raise fail(f"'motor' must be [pivot, tip], two different joints in 0..{n - 1}")
        ee = data.get("end_effector")
        if not _is_index(ee, n):
            raise fail(f"'end_effector' must be a joint index in 0..{n - 1}, got {ee!r}")
        if fixed[ee]:
            raise fail(f"'end_effector' {ee} is a fixed joint: it traces no path")
        crank_range = data.get("crank_range")
        if crank_range is not None:
            problem = crank_range_problem(crank_range)
            if problem:
                raise fail(f"'crank_range' {problem}")
        known = {"format", "units", "nodes", "links", "motor", "end_effector", "crank_range"}
        extra = {k: v for k, v in data.items() if k not in known}
        return cls(np.array(positions), np.array(fixed), tuple(seen), motor, ee, units, extra,
                   None if crank_range is None else tuple(crank_range))  # fmt: skip


def crank_range_problem(value: Any) -> str | None:
    """What is wrong with a crank range [a, b] (0 <= a < 2 pi, a < b <= a + 2 pi), or None."""
    if not (isinstance(value, (list, tuple)) and len(value) == 2 and all(map(_is_number, value))):
        return f"must be [a, b], two numbers (radians), got {value!r}"
    a, b = (float(v) for v in value)
    if not (math.isfinite(a) and math.isfinite(b)):
        return f"must be finite, got {list(value)!r}"
    if not 0 <= a < 2 * math.pi or not a < b <= a + 2 * math.pi + 1e-9:
        return f"must have 0 <= a < 2 pi and a < b <= a + 2 pi, got {list(value)!r}"
    return None


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_index(value: Any, n: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value < n


def _index_pair(value: Any, n: int) -> tuple[int, int] | None:
    if isinstance(value, list) and len(value) == 2 and all(_is_index(v, n) for v in value):
        return int(value[0]), int(value[1])
    return None


def _reject_constant(name: str) -> None:
    raise ValueError(f"{name} is not allowed")


def _reason(exc: Exception) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__
