"""`linkd bench TARGET`: throughput figures, printed (benchmarks, not tests).

Each target is a function taking the parsed arguments: to add one, give it a sub-parser in
`register` whose `run` default is that function.
"""

from __future__ import annotations

import argparse
import os
import re
import time
from pathlib import Path

from linkd.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="measure throughput (kinematics, generator, export, design)")
    targets = p.add_subparsers(dest="target", required=True, parser_class=type(p))

    k = targets.add_parser("kinematics", help="forward kinematics + validation, mechanisms/s")
    k.add_argument("--batch", type=int, default=20_000, help="20-joint mechanisms in the batch")
    k.add_argument("--angles", type=int, default=200, help="crank angles")
    k.add_argument("--repeat", type=int, default=3, help="timed runs (the best is reported)")
    k.add_argument("--chunk", type=int, default=512, help="mechanisms per kinematics chunk")
    k.add_argument("--eager", action="store_true", help="skip torch.compile (no C++ compiler)")
    k.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="processes, each validating its share of the batch")  # fmt: skip
    k.add_argument("--threads", type=int, default=1, help="torch threads per process")
    k.add_argument("--seed", type=int, default=0, help="seed of the random mechanisms")
    k.set_defaults(run=kinematics)

    g = targets.add_parser("generator", help="valid curated random mechanisms/s")
    g.add_argument("--count", type=int, default=20_000, help="mechanisms to generate")
    g.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes")
    g.add_argument("--seed", type=int, default=0, help="seed of the generator")
    g.set_defaults(run=generator)

    e = targets.add_parser("export", help="export and verify random mechanisms no test has seen")
    e.add_argument("--count", type=int, default=100, help="random mechanisms")
    e.add_argument("--seed", type=int, default=2026, help="seed of the generator")
    e.add_argument("--min-joints", type=int, default=5, help="fewest joints of a mechanism")
    e.add_argument("--max-joints", type=int, default=20, help="most joints of a mechanism")
    e.add_argument("--size", type=float, default=100.0, help="half the box they span, in mm")
    e.add_argument("--walkers", action="store_true",
                   help="Jansen walkers instead: one leg, a mirrored pair, and each on a crank "
                        "of three pins (8 to 36 joints)")  # fmt: skip
    e.add_argument("--bounds", action="store_true",
                   help="for each refused mechanism, what would have to be held otherwise "
                        "for it to layer, and whether brackets or rings could")  # fmt: skip
    e.set_defaults(run=export)

    d = targets.add_parser("design", help="linkd design on curves: validity, error, time")
    d.add_argument("curves", nargs="*", help="curve CSV files, or folders of them")
    d.add_argument("--dataset", help="also the test split of this data set folder")
    d.add_argument("--limit", type=int, help="at most this many curves")
    d.add_argument("--candidates", type=int, default=512, help="designs sampled per curve")
    d.add_argument("--strategy", default="node", choices=("node", "graph", "oneshot"),
                   help="LinkD's sampling: node- or graph-level retry, or one shot")  # fmt: skip
    d.add_argument("--no-refine", dest="refine", action="store_false",
                   help="place the designs on the curve without refining them")  # fmt: skip
    d.add_argument("--time-budget", type=float, default=30.0, help="seconds per curve")
    d.add_argument("--seed", type=int, default=0, help="seed of the sampling and search")
    d.add_argument("--model", help="LinkD checkpoint (default: the shipped one)")
    d.add_argument("--proposer", default="model", choices=("model", "random"),
                   help="candidates from LinkD or from the curve-blind generator")  # fmt: skip
    d.add_argument("--guidance", type=float,
                   help="LinkD guidance scale (default: 1, as in `linkd design`)")  # fmt: skip
    d.add_argument("--json", help="also write the figures to this JSON file")
    d.add_argument("--setup", default="plain",
                   choices=("plain", "user", "constrained", "no-motor"),
                   help="curves as given; placed in a user's frame (mm); or placed there "
                        "with designer's constraints around each, with or without the motor "
                        "point (linkd.design.bench)")  # fmt: skip
    d.add_argument("--path", default="auto", choices=("auto", "closed", "open"),
                   help="what the curves are (auto: an index.csv's closed column, else the gap "
                   "between the ends)")  # fmt: skip
    d.add_argument("--only", choices=("open", "closed"), help="only the open or closed curves")
    d.add_argument("--timed", action="store_true", help="rows equally spaced in time")
    from linkd.commands.design import add_search_options

    add_search_options(d)
    d.set_defaults(run=design)


def kinematics(args: argparse.Namespace) -> int:
    """Validate one batch of random valid 20-joint mechanisms at `--angles` crank angles.

    The batch is split over `--workers` processes. Each compiles its kernel before the clock
    starts; the time covers sending the batch, forward kinematics, validation, the verdicts back.
    Small single-threaded processes beat torch's threads here: a fused step is too short to
    share across threads.
    """
    import multiprocessing

    import numpy as np

    from linkd.batch import LinkageBatch
    from linkd.dataset import generate_parallel
    from linkd.generator import GeneratorSettings

    settings = GeneratorSettings(min_nodes=20, max_nodes=20, n_angles=args.angles)
    workers = max(1, args.workers)
    graphs = generate_parallel(args.batch, args.seed, workers, settings, shard_size=2000).graphs
    parts = [LinkageBatch.from_graphs(g) for g in np.array_split(graphs, workers)]
    config = (args.angles, args.chunk, not args.eager, args.threads)
    with multiprocessing.get_context("spawn").Pool(workers, _warm_up, (config,)) as pool:
        start = time.perf_counter()
        pool.map(_pause, range(workers))  # every worker has compiled and is waiting
        warm = time.perf_counter() - start
        best, valid = float("inf"), 0.0
        for _ in range(args.repeat):
            start = time.perf_counter()
            verdicts = pool.map(_validate, parts, chunksize=1)
            best = min(best, time.perf_counter() - start)
            valid = float(np.mean(np.concatenate(verdicts) == 0))
    kernel = "eager torch" if args.eager else "torch.compile"
    print(f"kinematics + validation: {args.batch} mechanisms x 20 joints x {args.angles} angles")
    print(f"  kernel         {kernel} (warm-up {warm:.1f} s)")
    print(f"  processes      {workers} x {args.threads} torch thread(s), chunks of {args.chunk}")
    print(f"  valid          {valid:.1%}")
    print(f"  best of {args.repeat}      {best:.3f} s")
    print(f"  throughput     {args.batch / best:,.0f} mechanisms/s")
    return 0


_CONFIG: tuple = ()


def _warm_up(config: tuple) -> None:
    """Worker set-up: torch threads, and one small validation to compile the kernel."""
    import torch

    from linkd import classic
    from linkd.batch import LinkageBatch

    global _CONFIG
    _CONFIG = config
    torch.set_num_threads(config[3])
    _validate(LinkageBatch.from_mechanisms([classic.jansen_leg()] * 4))


def _pause(_: int) -> None:
    time.sleep(0.2)


def _validate(batch) -> object:
    """Worker: the verdict of every mechanism of its share of the batch."""
    from linkd.validator import validate

    angles, chunk, compiled, _ = _CONFIG
    return validate(batch, angles, chunk=chunk, compiled=compiled).status


def design(args: argparse.Namespace) -> int:
    """The design pipeline on each curve (see `linkd.design.bench`)."""
    from linkd.design.bench import main

    return main(args)


def generator(args: argparse.Namespace) -> int:
    """Generate `--count` curated mechanisms with `--workers` processes (no files written)."""
    from linkd.dataset import generate_parallel

    start, start_cpu = time.perf_counter(), _cpu_seconds()
    samples = generate_parallel(args.count, args.seed, args.workers)
    seconds, cpu = time.perf_counter() - start, _cpu_seconds() - start_cpu
    counts = {int(n): int((samples.n_nodes == n).sum()) for n in sorted(set(samples.n_nodes))}
    print(f"generator: {len(samples)} valid curated mechanisms")
    print(f"  workers        {args.workers}")
    print(f"  node counts    {min(counts)}..{max(counts)}, {min(counts.values())} to "
          f"{max(counts.values())} each")  # fmt: skip
    print(f"  seconds        {seconds:.2f} ({cpu:.2f} s of CPU time, workers included)")
    print(f"  throughput     {len(samples) / seconds:,.0f} mechanisms/s "
          f"({len(samples) / seconds * 3600 / 1e6:.2f} M per hour)")  # fmt: skip
    return 0


def export(args: argparse.Namespace) -> int:
    """Export (MJCF + STL) and verify in MuJoCo `--count` generated mechanisms of `--min-joints`
    to `--max-joints` joints; a mechanism too tangled for flat layers, straight, bent, strapped,
    split, on brackets, on ground stubs or forked, is refused by the export and counted, and
    named by its number in the run (`generate`'s order) so it can be rebuilt. With `--walkers`,
    the Jansen walkers of `linkd.classic` instead: mechanisms a user would bring."""
    import tempfile
    from collections import Counter

    import numpy as np

    from linkd.classic import jansen_walker
    from linkd.export import NARROWER, TIMESTEP
    from linkd.export.bounds import bounds
    from linkd.export.options import resolve_sizes
    from linkd.export.parts import assemble
    from linkd.generator import MAX_NODES, GeneratorSettings, generate
    from linkd.geometry import Similarity
    from linkd.graph import from_graph
    from linkd.verified import export_verified

    if not 5 <= args.min_joints <= args.max_joints <= MAX_NODES:
        raise InputError(f"joint counts must satisfy 5 <= --min-joints <= --max-joints <= "
                         f"{MAX_NODES}, got {args.min_joints} and {args.max_joints}")  # fmt: skip
    if args.walkers:
        what = "Jansen walkers (linkd.classic.jansen_walker)"
        mechanisms = {f"{phases} pin(s), {'mirrored' if mirrored else 'one leg each'}":
                      jansen_walker(phases, mirrored)
                      for phases in (1, 3) for mirrored in (False, True)}  # fmt: skip
    else:
        what = f"random mechanisms of {args.min_joints} to {args.max_joints} joints"
        what += f" (seed {args.seed})"
        settings = GeneratorSettings(min_nodes=args.min_joints, max_nodes=args.max_joints)
        graphs = generate(args.count, args.seed, settings).graphs
        mechanisms = {f"no. {n}": from_graph(graph, Similarity(scale=args.size))
                      for n, graph in enumerate(graphs)}  # fmt: skip
    outcome, failed, layers, seconds, refusals = Counter(), Counter(), [], [], []
    refused_ones, failed_ones = [], []  # their names in the run (to rebuild them)
    bounded = []  # with --bounds: each refused one's
    slowest = (0.0, "")  # the longest export + verify, and its name
    for name, mech in mechanisms.items():
        width = resolve_sizes(mech, assemble(mech).parts, None).link_width
        with tempfile.TemporaryDirectory(prefix="linkd-bench-") as out:
            start = time.perf_counter()
            try:
                result, report = export_verified(mech, Path(out), {"mjcf", "stl"})
            except ValueError:
                outcome["refused (no flat layering)"] += 1
                refusals.append(time.perf_counter() - start)
                refused_ones.append(f"{name} ({len(mech.positions)} joints)")
                if args.bounds:
                    bounded.append(f"{name}: {bounds(mech, NARROWER[-1]).describe()}")
                continue
            seconds.append(time.perf_counter() - start)
            slowest = max(slowest, (seconds[-1], name))
        layers.append(result.layers)
        outcome["verified" if report.passed else "failed verification"] += 1
        if report.passed and result.sizes["link_width"] < width:
            outcome["  of which with narrower links"] += 1
        if report.passed and any("bends" in part for part in result.parts):
            outcome["  of which with bent links"] += 1
        pins = [part for part in result.parts if part["kind"] == "pin"]
        framed = any("_frame" in part["name"] for part in result.parts)  # its own rods and posts
        if report.passed and framed:
            outcome["  of which between frames"] += 1
        forked = not framed and any(re.fullmatch(r"pin_\d+[a-z]", pin["name"]) for pin in pins)
        if report.passed and forked:
            outcome["  of which forked"] += 1
            cut = {pin["fixed_in"] for pin in pins if re.fullmatch(r"pin_\d+[a-z]", pin["name"])}
            if len(cut) >= 2:
                outcome["    several parts at once"] += 1
        if report.passed and any(part["kind"] == "sheave" for part in result.parts):
            outcome["  of which strapped"] += 1
        split = not (forked or framed) and any("arm_of" in part for part in result.parts)
        if report.passed and split:
            outcome["  of which with split plates"] += 1
        arms: dict[str, list[set]] = {}
        for part in result.parts:
            if "arm_of" in part:
                arms.setdefault(part["arm_of"], []).append(set(part["joints"]))
        if report.passed and any(not set.intersection(*cut) for cut in arms.values()):
            outcome["    cut along their links"] += 1  # not a star: no joint in every arm
        turned = bool(result.turntables or result.lugged)  # posts hold their rings
        if report.passed and result.turntables:
            outcome["  of which on turntables"] += 1
        if report.passed and result.lugged:
            outcome["  of which on ground rings"] += 1
        posted = any(part["kind"] == "post" for part in result.parts)
        if report.passed and posted and not (framed or turned):
            outcome["  of which on a bracket"] += 1
        if report.passed and any(pin["name"].endswith("_top") for pin in pins):
            outcome["  of which on ground stubs"] += 1  # a pin and a stub at one joint
        if report.passed and result.drive:
            outcome["  of which with the crank cut in two"] += 1
        if report.passed and report.check("dynamics").figures["timestep_s"] < TIMESTEP:
            outcome["  of which with a finer step"] += 1
        failed.update(report.failed)
        if not report.passed:
            failed_ones.append(f"{name} ({', '.join(report.failed)})")
    print(f"export: {len(mechanisms)} {what}")
    for name in ("verified", "  of which between frames",
                 "  of which with narrower links", "  of which with bent links",
                 "  of which with split plates", "    cut along their links",
                 "  of which strapped", "  of which on a bracket", "  of which forked",
                 "    several parts at once", "  of which on turntables",
                 "  of which on ground rings", "  of which on ground stubs",
                 "  of which with the crank cut in two", "  of which with a finer step",
                 "failed verification",
                 "refused (no flat layering)"):  # fmt: skip
        if outcome[name]:
            print(f"  {name:28s} {outcome[name]}")
    if failed:
        print("  failed checks                " + ", ".join(f"{k} {v}" for k, v in failed.items()))
        print(f"  the failed ones              {', '.join(failed_ones)}")
    if seconds:
        print(f"  layers                       {min(layers)}..{max(layers)}, "
              f"mean {np.mean(layers):.1f}, median {np.median(layers):g}")  # fmt: skip
        print(f"  export + verify seconds      median {np.median(seconds):.2f}, "
              f"max {max(seconds):.2f} ({slowest[1]})")  # fmt: skip
    if refusals:  # what a user waits to be told no
        print(f"  seconds to refuse            median {np.median(refusals):.2f}, "
              f"max {max(refusals):.2f}")  # fmt: skip
        print(f"  the refused ones             {', '.join(refused_ones)}")
    for line in bounded:
        print(f"  bounds ({NARROWER[-1]:g} of the width)    {line}")
    return 0


def _cpu_seconds() -> float:
    """CPU time of this process and its finished child processes."""
    import resource

    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime
