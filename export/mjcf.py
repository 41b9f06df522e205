"""The MuJoCo model (MJCF) of an assembled, layered mechanism, and its scene.

Every part is a body whose frame sits at its hinge in the plane z = 0, with its plate raised to
its layer; hinges turn about z. Loops close with `connect` equalities between sites in that
common plane, so closing them asks nothing along z. Pins are cylinders on their hub's body,
spanning exactly the layers of the parts they join, and excluded from contact with those parts
only. Lengths are metres (CONTRACT §3).

Simulation options. Loop closures are soft constraints in MuJoCo; the stiffest safe setting is a
time constant of two time steps (`solref`) with impedance near 1 (`solimp` 0.9999). With RK4 at
0.5 ms, a 2 s motor revolution of the Jansen leg keeps its loops closed to 8e-8 of its shortest
link (the contract asks 1e-6; at 1 ms it is 3e-7, at 2 ms 1.3e-6), but random mechanisms close
to a toggle pose reached 1.2e-6 (2 of 62 in `linkd bench export`), so the step is 0.25 ms, which
brings those to 3e-7; implicitfast needs 50 us and runs five times slower. Verification
turns the crank in 1 s (twice as fast, so the loop error grows fourfold): 34 random mechanisms
stay within 5e-7 of their shortest link (median 3e-8), in half the simulated steps. A model
that still misses the tolerances at that step is written again with a finer one (`retimed`; the
step is chosen by `linkd.verified`). The crank servo is critically damped at 10 Hz for the largest
inertia the crank drives, and the crank hinge carries a rotor inertia of that size: without it
a light crank's own mode under the servo is too fast for RK4 (see `servo.servo_gains`). The Newton
solver with a tight tolerance converges in a few iterations.
"""

from __future__ import annotations

import itertools
import xml.etree.ElementTree as ET
from typing import TYPE_CHECKING

import numpy as np

from linkd.mechanism import UNITS_IN_METRES, Mechanism

from .layers import Layout
from .options import Sizes
from .parts import CRANK, Assembly, part_origins
from .planar import convex_hull
from .plates import Plate, plate_points, plates, posts, sheave_name
from .rods import pin_rods
from .servo import UNSIZED, Servo

if TYPE_CHECKING:
    import mujoco

TIMESTEP = 2.5e-4  # s, the default
CCD_TOLERANCE = 1e-6  # m, MuJoCo's own for the distance between convex meshes
CCD_SHARE = 0.01  # of the least gap between parts: the tolerance where that is finer, as a
# sub-millimetre mechanism's gaps (microns) come near MuJoCo's own, which then finds contacts
# between parts that do not touch
SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)
MIN_MASS, MIN_INERTIA = 1e-9, 1e-14  # kg, kg m^2: floors that only millimetre-sized designs reach
FLOOR_MARGIN = 10.0  # a model's lightest moving body stays this far above both floors
PROBE_DENSITY = 1e12  # times the density: a model at which no body of any buildable size is floored
SMALL_MESH = 1e-14  # m^3: MuJoCo refuses a mesh's exact inertia under 1e-15 (mjMINVAL); a plate
# of a millimetre-sized design below ten times that is weighed by its surface, its mass given
SITE_RADIUS = 0.15  # of the link width
LAYER_COLOURS = [(0.55, 0.55, 0.55), (0.85, 0.45, 0.2), (0.2, 0.55, 0.8), (0.35, 0.7, 0.35),
                 (0.8, 0.7, 0.2), (0.6, 0.4, 0.75), (0.3, 0.7, 0.7), (0.8, 0.35, 0.5)]  # fmt: skip


def _fmt(*values: float) -> str:
    """Numbers as MJCF text, each the shortest that reads back exactly (a whole number without
    its ".0"): a mechanism far from the origin keeps its joints where they are, to the bit."""
    return " ".join(repr(float(v)).removesuffix(".0") for v in values)


class _Builder:
    """Writes the model's XML tree part by part; lengths converted to metres on the way."""

    def __init__(self, mech, assembly: Assembly, layout: Layout, sizes: Sizes, armature: float,
                 small: dict[str, float]):  # fmt: skip
        self.mech, self.assembly, self.layout = mech, assembly, layout
        self.armature = armature
        self.density, self.small = sizes.density, small
        self.unit = UNITS_IN_METRES[mech.units]
        self.width = sizes.link_width * self.unit
        self.hole = sizes.hole_diameter * self.unit
        self.thickness = sizes.thickness * self.unit
        self.pitch = sizes.pitch * self.unit
        self.origin = part_origins(mech, assembly)
        self.sites: dict[tuple[int, int], str] = {}
        self.bodies: dict[int, ET.Element] = {}
        self.sheaves: dict[tuple[int, int], ET.Element] = {}  # (part, joint): its sheave's body

    def local(self, part: int, joint: int) -> np.ndarray:
        """Position of a mechanism joint in a part's body frame, in metres."""
        return (self.mech.positions[joint] - self.origin[part]) * self.unit

    def site(self, part: int, joint: int, name: str | None = None) -> str:
        """A site on `part` at `joint`, in the common plane z = 0 (created once). At the centre
        of one of the part's sheaves it is on the sheave's body: MuJoCo softens a loop closure
        by its anchors' bodies' inverse weights, and a part's body may be a massless hub on its
        own axis (the layshaft), whose weight it estimates as next to nothing."""
        key = (part, joint) if name is None else (part, name)
        if key not in self.sites:
            name = name or f"{self.assembly.parts[part].name}_at_{joint}"
            sheave = self.sheaves.get((part, joint))
            body, (x, y) = (self.bodies[part], self.local(part, joint)) if sheave is None else (
                sheave, (0.0, 0.0))  # fmt: skip
            ET.SubElement(body, "site", name=name, pos=_fmt(x, y, 0))
            self.sites[key] = name
        return self.sites[key]

    def bodies_tree(self, worldbody: ET.Element, meshes: dict[str, str]) -> None:
        """Nested bodies, parents first: each with its hinge (the ground has none) and plates."""
        every = plates(self.assembly, self.layout)
        ground = self.assembly.parts[0].name
        self.bodies[0] = ET.SubElement(worldbody, "body", name=ground,
                                       pos=_fmt(*self.origin[0] * self.unit, 0))  # fmt: skip
        for plate in every:
            if plate.part == 0:
                self.plate(plate, meshes)
        self.posts()
        moving: dict[int, list[Plate]] = {}
        for plate in every:
            if plate.part:
                moving.setdefault(plate.part, []).append(plate)
        for h in self.assembly.hinges:
            x, y = (self.origin[h.child] - self.origin[h.parent]) * self.unit
            name = self.assembly.parts[h.child].name
            body = ET.SubElement(self.bodies[h.parent], "body", name=name, pos=_fmt(x, y, 0))
            joint = ET.SubElement(body, "joint", name=h.name)
            if h.name == CRANK and self.armature > 0:
                joint.set("armature", _fmt(self.armature))
            self.bodies[h.child] = body
            for plate in moving[h.child]:
                self.plate(plate, meshes)

    def plate(self, plate: Plate, meshes: dict[str, str]) -> None:
        """A plate on its layer: its mesh, or boxes along its hull and discs at its joints. A
        bent link is a chain of bars: a mesh per bar, or boxes with discs at the bends."""
        body = self.bodies[plate.part]
        z = plate.layer * self.pitch
        colour = _fmt(*LAYER_COLOURS[plate.layer % len(LAYER_COLOURS)], 1)
        points = (plate_points(self.mech, plate) - self.origin[plate.part]) * self.unit
        if plate.sheave:  # a journal like a pin: a cylinder on a body of its own, welded on
            sheave = ET.SubElement(body, "body", name=plate.name, pos=_fmt(*points[0], 0))
            self.sheaves[plate.part, plate.joints[0]] = sheave
            ET.SubElement(sheave, "geom", name=plate.name, type="cylinder", rgba=colour,
                          size=_fmt(plate.sheave * self.unit, self.thickness / 2),
                          pos=_fmt(0, 0, z + self.thickness / 2))  # fmt: skip
            return
        if plate.disc and not plate.bore and plate.name not in meshes:  # a turntable's disc
            ET.SubElement(body, "geom", name=plate.name, type="cylinder", rgba=colour,
                          size=_fmt(plate.disc * self.unit, self.thickness / 2),
                          pos=_fmt(*points[0], z + self.thickness / 2))  # fmt: skip
            return
        bends = (np.reshape(plate.bends, (-1, 2)) - self.origin[plate.part]) * self.unit
        chain = np.concatenate([points[:1], bends, points[1:]]) if plate.bends else points
        if plate.bore:
            pieces = sorted((n for n in meshes if n.startswith(f"{plate.name}_piece")),
                            key=lambda n: int(n.rsplit("piece", 1)[1]))  # fmt: skip
            if not pieces:
                self.strap(plate, points, z, colour)
                return
        else:
            pieces = [f"{plate.name}_bar{k}" for k in range(len(chain) - 1)] if plate.bends else []
        if plate.name in meshes or (pieces and pieces[0] in meshes):
            for name in pieces or [plate.name]:
                geom = ET.SubElement(body, "geom", name=name, type="mesh", mesh=name,
                                     pos=_fmt(0, 0, z), rgba=colour)  # fmt: skip
                if name in self.small:  # a shell's density is per area: give its solid mass
                    geom.set("mass", _fmt(self.density * self.small[name]))
            return
        if plate.bends:
            sides = list(itertools.pairwise(chain))
        else:
            hull = [points[k] for k in convex_hull(points)]
            sides = list(zip(hull, hull[1:] + hull[:1])) if len(hull) > 2 else [tuple(hull)]
            sides = sides if len(hull) > 1 else []  # a lone joint (the ground at one pivot): a boss
        zc = z + self.thickness / 2
        for k, (a, b) in enumerate(sides):
            if np.linalg.norm(b - a) > 0:
                self.box(plate.part, f"{plate.name}_bar{k}", (a, b), self.width, zc, colour)
        posts = points[len(plate.joints) :]  # a disc round each post, named apart from the post
        discs = [*zip((f"boss{j}" for j in plate.joints), points),
                 *zip((f"post{k}_boss" for k in range(len(posts))), posts),
                 *zip((f"bend{k}" for k in range(len(bends))), bends)]  # fmt: skip
        for name, (x, y) in discs:
            ET.SubElement(body, "geom", name=f"{plate.name}_{name}", type="cylinder",
                          size=_fmt(self.width / 2, self.thickness / 2), pos=_fmt(x, y, zc),
                          rgba=colour)  # fmt: skip

    def strap(self, plate: Plate, points: np.ndarray, z: float, colour: str) -> None:
        """A strap without meshes (`meshes.strap_meshes`): its ring as boxes whose inner faces
        touch the bore, a bar and a boss out to each other joint, and their hull's sides but
        for a ground ring's; a turntable's ring is the boxes alone, corners on its rim."""
        centre, bore, zc = points[0], plate.bore * self.unit, z + self.thickness / 2
        sides = 64
        rim = plate.disc * self.unit * np.cos(np.pi / sides)  # a turntable ring's: corners on it
        outer = rim if plate.disc else bore + self.width / 2
        middle, half = (bore + outer) / 2, outer * np.tan(np.pi / sides)
        for k in range(sides):
            angle = (k + 0.5) * 2 * np.pi / sides
            out = np.array([np.cos(angle), np.sin(angle)])
            along = np.array([-out[1], out[0]]) * half
            chord = (centre + middle * out - along, centre + middle * out + along)
            self.box(plate.part, f"{plate.name}_ring{k}", chord, outer - bore, zc, colour)
        if plate.disc:
            return
        for k, point in enumerate(points[1:]):
            out = (point - centre) / np.linalg.norm(point - centre)
            bar = (centre + (bore + self.width / 2) * out, point)
            self.box(plate.part, f"{plate.name}_bar{k}", bar, self.width, zc, colour)
            ET.SubElement(self.bodies[plate.part], "geom", name=f"{plate.name}_boss{k}",
                          type="cylinder", size=_fmt(self.width / 2, self.thickness / 2),
                          pos=_fmt(*point, zc), rgba=colour)  # fmt: skip
        hull = [points[1:][k] for k in convex_hull(points[1:])]
        edges = list(zip(hull, hull[1:] + hull[:1])) if len(hull) > 2 else [tuple(hull)]
        for k, edge in enumerate(edges if len(hull) > 1 and plate.part else []):
            self.box(plate.part, f"{plate.name}_side{k}", edge, self.width, zc, colour)

    def box(self, part: int, name: str, ends: tuple, width: float, zc: float, colour: str) -> None:
        """A box geom of a plate's thickness and `width` from one point to another (part frame)."""
        a, b = ends
        (x, y), angle = (a + b) / 2, np.arctan2(*(b - a)[::-1])
        ET.SubElement(self.bodies[part], "geom", name=name, type="box", rgba=colour,
                      size=_fmt(np.linalg.norm(b - a) / 2, width / 2, self.thickness / 2),
                      pos=_fmt(x, y, zc), euler=_fmt(0, 0, angle))  # fmt: skip

    def posts(self) -> None:
        """The ground's posts: rods of the pin diameter, from the base plate up to a bracket or
        from a bracket up to the cover, or from base to cover holding the frames."""
        name = self.assembly.parts[0].name
        for k, (point, (lo, hi)) in enumerate(posts(self.layout)):
            bottom, top = lo * self.pitch, hi * self.pitch + self.thickness
            x, y = (np.asarray(point) - self.origin[0]) * self.unit
            ET.SubElement(self.bodies[0], "geom", name=f"{name}_post{k}", type="cylinder",
                          size=_fmt(self.hole / 2, (top - bottom) / 2),
                          pos=_fmt(x, y, (top + bottom) / 2), rgba="0.75 0.75 0.78 1")  # fmt: skip

    def rod(self, part: int, name: str, joint: int, span: tuple[int, int]) -> None:
        """A pin (or a split part's shaft) as a body welded to `part`, over the layers `span`."""
        lo, hi = span
        bottom, top = lo * self.pitch, hi * self.pitch + self.thickness
        x, y = self.local(part, joint)
        body = ET.SubElement(self.bodies[part], "body", name=name, pos=_fmt(x, y, 0))
        ET.SubElement(body, "geom", name=name, type="cylinder",
                      size=_fmt(self.hole / 2, (top - bottom) / 2),
                      pos=_fmt(0, 0, (top + bottom) / 2), rgba="0.75 0.75 0.78 1")  # fmt: skip


def build_mjcf(
    mech: Mechanism,
    assembly: Assembly,
    layout: Layout,
    sizes: Sizes,
    meshes: dict[str, str] | None = None,
    servo: Servo = UNSIZED,
    volumes: dict[str, float] | None = None,
) -> str:
    """The model as MJCF text. `meshes` maps part names to STL paths relative to the model file;
    without it the plates are boxes and cylinders. `volumes` (m^3, by mesh name) finds the
    meshes too small for MuJoCo's exact inertia: those take a shell inertia and their mass."""
    small = {name: v for name, v in (volumes or {}).items() if v < SMALL_MESH}
    b = _Builder(mech, assembly, layout, sizes, servo.armature, small)
    root = ET.Element("mujoco", model="linkd mechanism")
    ET.SubElement(root, "compiler", angle="radian", autolimits="true",
                  boundmass=_fmt(MIN_MASS), boundinertia=_fmt(MIN_INERTIA))  # fmt: skip
    option = ET.SubElement(root, "option", timestep=_fmt(TIMESTEP), integrator="RK4",
                           solver="Newton", iterations="50", tolerance="1e-12")  # fmt: skip
    gap = min(sizes.layer_gap, sizes.clearance) * b.unit
    if CCD_SHARE * gap < CCD_TOLERANCE:
        option.set("ccd_tolerance", _fmt(CCD_SHARE * gap))
    ET.SubElement(option, "flag", filterparent="disable")
    default = ET.SubElement(root, "default")
    ET.SubElement(default, "joint", type="hinge", axis="0 0 1")
    ET.SubElement(default, "geom", density=_fmt(sizes.density))
    ET.SubElement(default, "equality", solref=_fmt(*solref(TIMESTEP)), solimp=_fmt(*SOLIMP))
    ET.SubElement(default, "site", size=_fmt(SITE_RADIUS * b.width), rgba="0.9 0.1 0.1 1")
    if meshes:
        asset = ET.SubElement(root, "asset")
        for name, path in meshes.items():
            inertia = "shell" if name in small else "exact"
            ET.SubElement(asset, "mesh", name=name, file=path, inertia=inertia)
    b.bodies_tree(ET.SubElement(root, "worldbody"), meshes or {})
    contact = ET.SubElement(root, "contact")
    rods = pin_rods(assembly, layout)
    for rod in rods:
        b.rod(rod.hub, rod.name, rod.joint, rod.span)
        for m in rod.members:
            if m != rod.hub:
                ET.SubElement(contact, "exclude", body1=rod.name, body2=assembly.parts[m].name)
    for shaft in layout.shafts:
        b.rod(shaft.part, shaft.name, shaft.joint, shaft.span)
    for strap in layout.straps:  # the strap turns on its sheave, the pins pass through it
        name = sheave_name(assembly, layout, strap)
        ET.SubElement(contact, "exclude", body1=name, body2=assembly.parts[strap.part].name)
        through = {strap.joint, *(assembly.pins[k].joint for k in strap.passing)}
        for rod in rods:
            if rod.joint in through:
                ET.SubElement(contact, "exclude", body1=name, body2=rod.name)
    equality = ET.SubElement(root, "equality")
    for loop in assembly.loops:
        ET.SubElement(equality, "connect", name=loop.name, site1=b.site(loop.part, loop.joint),
                      site2=b.site(loop.hub, loop.joint))  # fmt: skip
    ee = mech.end_effector
    carrier = next((pin.hub for pin in assembly.pins if pin.joint == ee), None)
    if carrier is None:
        carrier = next(p for p, part in enumerate(assembly.parts) if ee in part.joints)
    b.site(carrier, ee, name="end_effector")
    actuator = ET.SubElement(root, "actuator")
    ET.SubElement(actuator, "position", name="motor", joint=CRANK, kp=_fmt(servo.kp),
                  kv=_fmt(servo.kv), ctrllimited="false")  # fmt: skip
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"


def density_scale(probe: mujoco.MjModel) -> float:
    """The power of ten by which to raise the density so that every moving body's own mass and
    inertia lie FLOOR_MARGIN above MuJoCo's floors (1 where they do), from the model compiled at
    PROBE_DENSITY times the density (about 10 ms). Millimetre-sized parts weigh less than the
    floors: raised to them, every light part would weigh the same and turn like a flywheel, and
    the loops would need a step tens of times finer. Scaling every mass alike changes no motion
    (the mechanism moves in the plane, gravity along z, and the servo is sized from the model)."""
    # a moving body with no geom of its own (a layshaft) weighs with its welded shaft and sheaves
    weld, bare = probe.body_weldid, probe.body_geomnum == 0
    groups = [weld == b if bare[b] else [b] for b in np.flatnonzero(probe.body_dofnum > 0)]
    mass = min(probe.body_mass[g].sum() for g in groups) / PROBE_DENSITY
    inertia = min(probe.body_inertia[g].sum(0).min() for g in groups) / PROBE_DENSITY
    need = FLOOR_MARGIN * max(MIN_MASS / mass, MIN_INERTIA / inertia)
    return float(10 ** np.ceil(np.log10(need))) if need > 1 else 1.0


def solref(timestep: float) -> tuple[float, float]:
    """The loop closures' time constant, at MuJoCo's floor of two steps, and damping ratio."""
    return 2 * timestep, 1.0


def retimed(xml: str, timestep: float) -> str:
    """The model text `build_mjcf` wrote, with another time step and the loop closures kept at
    two steps (the same text when the step is the same)."""
    root = ET.fromstring(xml)
    root.find("option").set("timestep", _fmt(timestep))
    root.find("default/equality").set("solref", _fmt(*solref(timestep)))
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"


def build_scene(mech: Mechanism, layout: Layout, sizes: Sizes, model_file: str) -> str:
    """A scene that includes the model, with a floor under the lowest layer and a light."""
    unit = UNITS_IN_METRES[mech.units]
    centre = mech.positions.mean(0) * unit
    extent = 3 * mech.scale * unit
    height = (layout.count * sizes.pitch) * unit
    lowest = min(0, layout.drive.layers[0]) if layout.drive else 0  # the drive's under the base
    root = ET.Element("mujoco", model="linkd mechanism scene")
    ET.SubElement(root, "include", file=model_file)
    ET.SubElement(root, "statistic", center=_fmt(*centre, height / 2), extent=_fmt(extent))
    visual = ET.SubElement(root, "visual")
    ET.SubElement(visual, "headlight", diffuse="0.6 0.6 0.6", ambient="0.3 0.3 0.3")
    ET.SubElement(visual, "global", azimuth="120", elevation="-30")
    asset = ET.SubElement(root, "asset")
    ET.SubElement(asset, "texture", name="grid", type="2d", builtin="checker", width="512",
                  height="512", rgb1="0.92 0.92 0.92", rgb2="0.84 0.84 0.84")  # fmt: skip
    ET.SubElement(asset, "material", name="grid", texture="grid", texuniform="true",
                  texrepeat=_fmt(4 / extent, 4 / extent), reflectance="0.1")  # fmt: skip
    worldbody = ET.SubElement(root, "worldbody")
    ET.SubElement(worldbody, "light", pos=_fmt(*centre, height + extent), dir="0 0 -1",
                  directional="true")  # fmt: skip
    ET.SubElement(worldbody, "geom", name="floor", type="plane", material="grid",
                  size=_fmt(0, 0, extent / 10),
                  pos=_fmt(*centre, (lowest * sizes.pitch - sizes.layer_gap) * unit))  # fmt: skip
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"
