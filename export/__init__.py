"""Export a mechanism as a MuJoCo model with z-layered parts and STL plates (CONTRACT §3-4).

    from linkd.export import export_mechanism
    result = export_mechanism(mech, Path("out"), {"mjcf", "stl"})

The mechanism is split into rigid parts (`parts`), each part gets a layer from a sweep of the
analytic kinematics (`layers`; where straight parts cannot be layered, links bend round
pins, `routing`; where bent ones cannot either, a mechanism made of modules on one crank is
stacked a module between two frame plates, `framed`, and otherwise a link or two may turn on
sheaves as eccentric straps, `strapped`, then plates are cut into arms and ground pins are
held by brackets or as two stubs from base and cover, `braced`, and failing that a part forks,
or several do, `forked`, then the parts at the motor's pivot turn on turntables, with forks
or straps beside them, `turntable`, then several links may be straps at once, beside a
turntable or not, then plates are cut into arms beside straps, `braced`, then the
motor's shaft is cut too, the crank's two halves turned as one from a layshaft, `drive`, and
last the parts at other ground pivots turn on rings held by lugs, `ground_rings`, alone or
beside forked parts, and then so may the crank, `forked_rings`), plates
become STL meshes (`meshes`, outlined by `plates`) and the bodies, hinges, pins, loop
closures and crank servo become `mechanism.xml` with a `scene.xml` around it (`mjcf`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from linkd.mechanism import UNITS_IN_METRES, Mechanism
from linkd.scale import MECHANISM_RANGE_M, size_problem
from linkd.topology import Status
from linkd.validator import validate_mechanism

from .braced import braced_layers, cut_crank_layers, split_straps_layers
from .described import describe_parts
from .drive import drive
from .forked import forked_layers
from .forked_rings import crank_ring_layers, forked_rings_layers
from .forked_straps import forked_straps_layers
from .framed import framed_layers, modular
from .ground_rings import ground_rings_layers
from .layers import Layout, assign_layers, find_conflicts, sweep
from .mjcf import (
    PROBE_DENSITY,
    TIMESTEP,
    build_mjcf,
    build_scene,
    density_scale,
    retimed,
)
from .options import ExportOptions, Sizes, resolve_sizes
from .parts import Assembly, assemble, hinge_angles, joint_paths, part_origins
from .plates import plate_points, plates
from .refusal import why_refused
from .routing import bent_layers
from .servo import qpos_at, servo_gains
from .strapped import several_straps_layers, strapped_layers
from .turntable import turntable_core_layers, turntable_layers

__all__ = ["FORMATS", "TIMESTEP", "ExportOptions", "ExportResult", "buildable",
           "export_mechanism", "hinge_angles", "joint_paths", "qpos_at",
           "set_timestep"]  # fmt: skip

FORMATS = frozenset({"mjcf", "stl"})
CONSTRUCTIONS = {assign_layers: "straight parts", bent_layers: "bent links",
                 framed_layers: "modules between frames", strapped_layers: "eccentric straps",
                 braced_layers: "split plates and brackets", forked_layers: "forked parts",
                 turntable_layers: "turntables at the motor's pivot",
                 several_straps_layers: "several eccentric straps at once",
                 turntable_core_layers: "a turntable with several straps",
                 split_straps_layers: "split plates with straps",
                 cut_crank_layers: "a crank cut in two, driven from a layshaft",
                 ground_rings_layers: "ground pivots on rings",
                 forked_rings_layers: "ground pivots on rings beside forked parts",
                 crank_ring_layers: "the crank on a ring beside forked parts",
                 forked_straps_layers: "straps beside forked parts"}  # fmt: skip
# Where frames build a mechanism, the straps still try for fewer layers, briefly: the 25 of the
# small benchmarks' mechanisms that both build each take a strap within 8 layer searches.
QUICK_STRAPS = 12
NARROWER = (0.5, 0.25)  # link widths tried, as fractions of the default, when it cannot layer
# Costly searches: after the usual width they are tried at the narrowest, where every size is
# smallest and so are the conflicts (a layering at a wider width is one there too); where the
# search finds none there, the widths between are not tried.
SCREENED = frozenset({braced_layers, forked_layers, turntable_layers, split_straps_layers,
                      cut_crank_layers, ground_rings_layers, forked_rings_layers,
                      crank_ring_layers, forked_straps_layers})  # fmt: skip
MODEL, SCENE, MESHES = "mechanism.xml", "scene.xml", "meshes"


@dataclass
class ExportResult:
    layers: int  # z-layer count
    parts: list  # part descriptions: name, kind (ground/link/plate/pin), joints, layer(s)
    files: list[Path]  # written files, relative to out_dir
    seconds: float
    sizes: dict = field(default_factory=dict)  # resolved sizes, mechanism units
    min_gap: float = float("inf")  # least in-plane gap between plates of one layer, mech units
    minimal: bool = True  # the layer count is proved minimal
    narrowed: float = 1.0  # link width over the usual one: below 1 where no wider one layered
    crank: str = ""  # the crank's part name
    turntables: tuple[str, ...] = ()  # the parts at the motor's pivot on turntables
    drive: str = ""  # the layshaft's name where the crank is cut in two and driven from it
    lugged: tuple[str, ...] = ()  # the parts at ground pivots on rings held by lugs

    @property
    def turntable(self) -> str | None:
        """The crank's name where it is a disc on a turntable, or a ring held by a lug (to be
        driven at its rim)."""
        return self.crank if self.crank in (*self.turntables, *self.lugged) else None

    @property
    def rings(self) -> tuple[str, ...]:
        """The other parts at the motor's pivot that turn in rings of their own."""
        return tuple(name for name in self.turntables if name != self.crank)


def export_mechanism(
    mech: Mechanism,
    out_dir: Path,
    formats: set[str] = FORMATS,
    options: ExportOptions | None = None,
    progress: Callable[[str], None] | None = None,
) -> ExportResult:
    """Write mechanism.json (with `layers` and `parts`), and per `formats` mechanism.xml with
    scene.xml ("mjcf") and meshes/*.stl ("stl") into the existing folder `out_dir`.
    `progress` is told what is being tried (the search for layers can take a minute).

    Raises ValueError for an invalid mechanism, an unknown format or impossible sizes.
    """
    start = time.perf_counter()
    out_dir = Path(out_dir)
    unknown = set(formats) - FORMATS
    if unknown:
        raise ValueError(f"unknown export format {', '.join(sorted(unknown))}")
    size = size_problem(mech.positions, mech.units, "mechanism", MECHANISM_RANGE_M)
    if size:
        raise ValueError(size)
    status, _ = validate_mechanism(mech)
    if status != Status.VALID:
        raise ValueError(f"invalid mechanism: {status.reason}")
    assembly = assemble(mech)
    say = progress or (lambda text: None)
    options = options or ExportOptions()
    sizes, layout = _layered(mech, assembly, options, progress=say)
    narrowed = sizes.link_width / resolve_sizes(mech, assembly.parts, options).link_width
    shapes, assembly, layout = drive(mech, assembly, layout, sizes)
    say(f"writing {layout.count} layers of parts")
    files: list[Path] = []
    meshes, wholes, volumes = {}, {}, {}
    if "stl" in formats:
        meshes, wholes, volumes = _write_meshes(shapes, assembly, layout, sizes, out_dir)
    files += [Path(path) for path in {*meshes.values(), *wholes.values()}]
    if "mjcf" in formats:
        sizes = _write_model(mech, shapes, assembly, layout, sizes, meshes, volumes, out_dir)
        files += [Path(MODEL), Path(SCENE)]
    parts = describe_parts(assembly, layout, sizes, wholes, meshes)
    extra = {key: value for key, value in mech.extra.items() if key != "drive"}
    extra |= {"layers": layout.count, "parts": parts}
    if layout.drive:
        extra["drive"] = layout.drive.describe()
    mech.replace(extra=extra).save(out_dir / "mechanism.json")
    files.append(Path("mechanism.json"))
    names = [part.name for part in assembly.parts]
    return ExportResult(layout.count, parts, sorted(files), time.perf_counter() - start,
                        sizes.to_dict(), layout.min_gap, layout.minimal, narrowed,
                        names[assembly.crank.child],
                        tuple(names[t.part] for t in layout.turntables if not t.spans),
                        names[layout.drive.layshaft] if layout.drive else "",
                        tuple(names[t.part] for t in layout.turntables if t.spans))  # fmt: skip


def _layered(
    mech: Mechanism,
    assembly: Assembly,
    options: ExportOptions,
    quick: bool = False,
    progress: Callable[[str], None] = lambda text: None,
) -> tuple[Sizes, Layout]:
    """Sizes and layers. Where the default link width leaves no flat layering (a part passes
    over a pin whose plates would lie above and below it, in every order), narrower links may
    leave room: the width, and the sizes derived from it, shrink by the NARROWER factors. Where
    no width does, binary links bend around the pins in their way (`routing`), at each width,
    then modules on one crank are stacked between frames (`framed`; where they build it, the
    first QUICK_STRAPS strap choices, at the frames' width or wider, may still do with fewer
    layers), then parts turn on sheaves as eccentric straps (`strapped`), and then plates are
    cut into arms and ground pins are held by brackets or as stubs from both plates
    (`braced`, unless `options.brackets` is off), then a part forks, then the parts at the
    motor's pivot turn on turntables (`turntable`); then several parts at once may be straps,
    then as many beside the crank on a turntable, then plates are cut into arms beside straps
    (`braced`), then the motor's shaft may be cut too (the crank in two halves, `drive`), then
    the parts at other ground pivots turn on rings held by lugs (`ground_rings`), then those
    rings beside forked parts, and last with the crank on a ring too (`forked_rings`); the
    forks, the turntables, the splits and the rings are SCREENED.
    Widths the user gave are kept (the other constructions are still tried; ValueError when
    nothing works). quick: straight links at the first width only. `progress` is told each
    construction and width."""
    sizes = resolve_sizes(mech, assembly.parts, options)
    tries = [sizes]
    if options.link_width is None and not quick:
        for fraction in NARROWER:
            narrow = replace(options, link_width=sizes.link_width * fraction)
            try:
                tries.append(resolve_sizes(mech, assembly.parts, narrow))
            except ValueError:  # too narrow for a hole the user gave
                break
    layerings = [assign_layers] if quick else [assign_layers, bent_layers, strapped_layers]
    if modular(assembly) and not quick:  # a quick small search, before the straps' large one
        layerings.insert(2, framed_layers)
    if options.brackets and not quick:
        layerings += [braced_layers, forked_layers, turntable_layers, several_straps_layers,
                      turntable_core_layers, split_straps_layers, cut_crank_layers,
                      ground_rings_layers, forked_rings_layers, crank_ring_layers,
                      forked_straps_layers]  # fmt: skip
    swept: dict[float, np.ndarray] = {}  # each width's sweep, made once for every layering

    def paths(size: Sizes) -> np.ndarray:
        if size.link_width not in swept:
            swept[size.link_width] = sweep(mech, size.link_width)
        return swept[size.link_width]

    first, framed = None, None  # framed: the frames' build, while the straps try briefly
    for layering in layerings:
        if framed is not None and layering is not strapped_layers:
            return framed
        build, screened = layering, layering in SCREENED and len(tries) > 2
        order = [tries[0], tries[-1], *tries[1:-1]] if screened else tries
        if framed is not None:  # the straps, briefly and no narrower than the frames
            build = partial(layering, searches=QUICK_STRAPS)
            order = tries[: tries.index(framed[0]) + 1]
        fallback = None  # a screened construction's layout at the narrowest width
        for size in order:
            fraction = size.link_width / sizes.link_width
            width = "the usual width" if fraction == 1 else f"{fraction:g} of the usual width"
            progress(f"layering {CONSTRUCTIONS[layering]} at {width}")
            try:
                layout = build(assembly, paths(size), size)
            except ValueError as exc:
                first = first or exc
                if screened and size is tries[-1]:
                    break  # none at the loosest width: the ones between are not tried
                continue
            if layering is framed_layers:
                framed = size, layout
                break
            if framed is not None:  # the straps' build, if it has fewer layers
                return min((size, layout), framed, key=lambda built: built[1].count)
            if not (screened and size is tries[-1]):
                return size, layout
            fallback = size, layout  # but a wider one between may layer too
        if fallback is not None:
            return fallback
    if framed is not None:
        return framed
    widths = f", down to {NARROWER[-1]:g} of the usual width" if len(tries) > 1 else ""
    culprits = ""
    if not quick:  # which pins, for the designer to move: found at the narrowest width tried
        progress("none layers: finding the pins that keep it from layering")
        narrowest = tries[-1]
        conflicts = find_conflicts(assembly, paths(narrowest), narrowest)
        why = why_refused(assembly, conflicts, narrowest)
        if why:
            culprits = f"; with straight parts, {why} alone cannot all be kept clear"
    frames = ", framed" if framed_layers in layerings else ""
    turned = ", turntables, ground rings" if turntable_layers in layerings else ""
    tried = f"straight, bent{frames}, strapped, split and forked parts{turned}{widths} tried"
    tried += culprits
    raise ValueError(f"{first} ({tried})")


def _write_meshes(
    mech: Mechanism, assembly: Assembly, layout: Layout, sizes: Sizes, out_dir: Path
) -> tuple[dict, dict, dict]:
    """One STL per plate in its body's frame, metres, and for a bent link also one per bar (its
    convex pieces, which the model collides). Returns the model's mesh name -> relative path,
    plate name -> relative path of its whole STL, and the model's mesh name -> volume (m^3)."""
    from .meshes import bent_mesh, disc_mesh, plate_mesh, ring_meshes, strap_meshes, write_stl

    unit = UNITS_IN_METRES[mech.units]
    origins = part_origins(mech, assembly)
    size = (sizes.link_width * unit, sizes.hole_diameter * unit, sizes.thickness * unit)
    (out_dir / MESHES).mkdir(exist_ok=True)
    model, whole, volumes = {}, {}, {}
    for plate in plates(assembly, layout):
        points = (plate_points(mech, plate) - origins[plate.part]) * unit
        whole[plate.name] = f"{MESHES}/{plate.name}.stl"
        if plate.sheave:  # the model's sheave is a cylinder, like a pin
            pinned = layout.drive is None or plate.joints[0] < layout.drive.first  # a pin there
            sheave = disc_mesh(points, plate.sheave * unit, *size[1:], pinned)
            write_stl(out_dir / whole[plate.name], sheave, plate.name)
            continue
        if plate.disc and not plate.bore:  # a turntable's: a plate whose hull is the disc
            solid = disc_mesh(points, plate.disc * unit, *size[1:], False)
            write_stl(out_dir / whole[plate.name], solid, plate.name)
            model[plate.name], volumes[plate.name] = whole[plate.name], solid.volume
            continue
        if plate.bore:  # a strap, a turntable's ring, or the ground's ring round one
            if plate.disc:
                solid, pieces = ring_meshes(points, plate.bore * unit, plate.disc * unit, *size[1:])
            else:
                solid, pieces = strap_meshes(points, plate.bore * unit, *size, hull=plate.part > 0)
            write_stl(out_dir / whole[plate.name], solid, plate.name)
            for k, piece in enumerate(pieces):
                name = f"{plate.name}_piece{k}"
                model[name], volumes[name] = f"{MESHES}/{name}.stl", piece.volume
                write_stl(out_dir / model[name], piece, name)
            continue
        if not plate.bends:
            solid = plate_mesh(points, *size)
            write_stl(out_dir / whole[plate.name], solid, plate.name)
            model[plate.name], volumes[plate.name] = whole[plate.name], solid.volume
            continue
        chain = np.concatenate([points[:1], (np.array(plate.bends) - origins[plate.part]) * unit,
                                points[1:]])  # fmt: skip
        write_stl(out_dir / whole[plate.name], bent_mesh(chain, *size), plate.name)
        for k in range(len(chain) - 1):
            name = f"{plate.name}_bar{k}"
            model[name] = f"{MESHES}/{name}.stl"
            bar = plate_mesh(chain[k : k + 2], *size, holes=points[[k == 0, k == len(chain) - 2]])
            write_stl(out_dir / model[name], bar, name)
            volumes[name] = bar.volume
    return model, whole, volumes


def _write_model(
    mech: Mechanism,
    shapes: Mechanism,
    assembly: Assembly,
    layout: Layout,
    sizes: Sizes,
    meshes: dict,
    volumes: dict,
    out: Path,
) -> Sizes:
    """mechanism.xml, with the model's mesh paths and volumes from `_write_meshes`, compiled
    to weigh its parts and to size the crank servo from its own inertia; returns the sizes with
    the density used, raised where MuJoCo's mass floors would distort a millimetre-sized model
    (`density_scale`). `shapes`: the mechanism with the drive's points, where there is one."""
    import mujoco

    path = out / MODEL

    def compiled(s: Sizes) -> mujoco.MjModel:
        path.write_text(build_mjcf(shapes, assembly, layout, s, meshes, volumes=volumes))
        return mujoco.MjModel.from_xml_path(str(path))

    scale = density_scale(compiled(replace(sizes, density=sizes.density * PROBE_DENSITY)))
    sizes = replace(sizes, density=sizes.density * scale)
    servo = servo_gains(compiled(sizes), mech, layout.drive)
    path.write_text(build_mjcf(shapes, assembly, layout, sizes, meshes, servo, volumes))
    (out / SCENE).write_text(build_scene(mech, layout, sizes, MODEL))
    return sizes


def set_timestep(out_dir: Path, timestep: float) -> None:
    """Write OUT/mechanism.xml again with another time step: stiffer loop closures for a model
    whose loops the default step leaves too soft (see `linkd.verified`)."""
    path = Path(out_dir) / MODEL
    path.write_text(retimed(path.read_text(), timestep))


def buildable(mech: Mechanism, options: ExportOptions | None = None, quick: bool = False) -> bool:
    """Whether `export_mechanism` would find sizes and layers for `mech`, without building or
    writing anything: the design search asks before it spends a round around a design that
    could never be delivered. quick: straight links at the first width only, what most
    designs that build need (a refusal costs a fraction of the full search's; a design it
    refuses may still build with narrower or bent links)."""
    try:
        _layered(mech, assemble(mech), options or ExportOptions(), quick)
    except ValueError:
        return False
    return True
