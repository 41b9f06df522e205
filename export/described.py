"""The parts list of mechanism.json: every plate, pin and post as a builder reads it (sizes in
the mechanism's units; docs/formats.md says what each key means)."""

from __future__ import annotations

from .layers import Layout
from .options import Sizes
from .parts import Assembly
from .plates import plates, posts
from .rods import keyed, pin_rods


def describe_parts(
    assembly: Assembly, layout: Layout, sizes: Sizes, wholes: dict, meshes: dict
) -> list[dict]:
    """JSON descriptions of the plates, pins and posts (sizes in the mechanism's units); a bent
    link also has its waypoints (`bends`, assembly pose) and the STL of each bar (`pieces`), an
    arm of a split part its part (`arm_of`), a ground plate holding posts their axes (`posts`)."""
    out, grounds = [], [p for p in plates(assembly, layout) if p.part == 0 and not p.sheave]
    for plate in plates(assembly, layout):
        entry = {"name": plate.name, "kind": assembly.parts[plate.part].kind,
                 "joints": list(plate.joints), "layer": plate.layer}  # fmt: skip
        if plate.part in layout.arms and not plate.sheave:
            entry["arm_of"] = assembly.parts[plate.part].name
        if plate.posts:
            entry["posts"] = [list(point) for point in plate.posts]
        if plate.bends:
            entry["bends"] = [list(point) for point in plate.bends]
        if plate.name in wholes:
            entry["mesh"] = wholes[plate.name]
        if plate.bends and wholes:
            entry["pieces"] = [meshes[f"{plate.name}_bar{k}"] for k in range(len(plate.bends) + 1)]
        if plate.bore:
            entry["bore"] = 2 * plate.bore
            if wholes:
                entry["pieces"] = [path for name, path in meshes.items()
                                   if name.startswith(f"{plate.name}_piece")]  # fmt: skip
        if plate.sheave:
            entry |= {"kind": "sheave", "diameter": 2 * plate.sheave,
                      "fixed_in": assembly.parts[plate.part].name}  # fmt: skip
        if plate.disc:
            entry["disc"] = 2 * plate.disc
        out.append(entry)
    fixed = {j: p for p, arms in layout.arms.items() for j in keyed(a.joints for a in arms)}
    fixed |= {assembly.pins[k].joint: fork.part for k, fork in layout.forks.items()}
    halved = {assembly.pins[k].joint for k, fork in layout.forks.items() if fork.hubs}
    if layout.drive:  # the motor's stubs, each fixed in its half of the crank
        halved.add(assembly.pins[layout.drive.pin].joint)
    fixed |= {strap.joint: strap.sheave_of for strap in layout.straps}  # the sheave's pin
    for rod in pin_rods(assembly, layout):
        lo, hi = rod.span
        entry = {
            "name": rod.name, "kind": "pin", "joints": [rod.joint], "layers": [lo, hi],
            "joins": [_ground_plate(grounds, rod) if m == 0 else assembly.parts[m].name
                      for m in rod.members],
            "diameter": sizes.hole_diameter, "length": (hi - lo) * sizes.pitch + sizes.thickness,
        }  # fmt: skip
        if rod.joint in halved:  # a rod in one half of a crank cut in two (`drive`)
            entry["fixed_in"] = assembly.parts[rod.hub].name
        elif rod.joint in fixed:
            entry["fixed_in"] = assembly.parts[fixed[rod.joint]].name
        elif rod.hub and 0 in rod.members:  # a shaft turning in the ground's plates (`drive`)
            entry["fixed_in"] = assembly.parts[rod.hub].name
        out.append(entry)
    for shaft in layout.shafts:
        lo, hi = shaft.span
        name = assembly.parts[shaft.part].name
        out.append({
            "name": shaft.name, "kind": "pin", "joints": [shaft.joint], "layers": [lo, hi],
            "joins": [name], "diameter": sizes.hole_diameter, "fixed_in": name,
            "length": (hi - lo) * sizes.pitch + sizes.thickness,
        })  # fmt: skip
    for k, (point, (lo, hi)) in enumerate(posts(layout)):
        out.append({
            "name": f"{assembly.parts[0].name}_post{k}", "kind": "post", "at": list(point),
            "layers": [lo, hi], "diameter": sizes.hole_diameter,
            "length": (hi - lo) * sizes.pitch + sizes.thickness,
        })  # fmt: skip
    return out


def _ground_plate(grounds: list, rod) -> str:
    """The ground plate a pin of the ground stands in: the base, the cover or a bracket, the one
    holding its joint on a layer it spans (an end, or a bracket a forked part's shaft turns in
    between its arms)."""
    lo, hi = rod.span
    return next(p.name for p in grounds if rod.joint in p.joints and lo <= p.layer <= hi)
