"""`curve.png`: the target curve, the traced path and the mechanism in its assembly pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from linkd.mechanism import Mechanism
from linkd.outdir import atomic_file

from .analytic import joint_paths, rigid_parts
from .screen import screen_polyline

ANGLES = 400


def write_curve_plot(mech: Mechanism, path: str | Path, target: np.ndarray | None = None) -> None:
    """Draw the plot with matplotlib (Agg, no display needed) and write it as PNG to `path`."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    if target is not None:
        target = screen_polyline(target[:, :2])
    paths = joint_paths(mech, ANGLES)
    traced = paths[mech.end_effector]
    fig = Figure(figsize=(6, 6), dpi=120)
    ax = fig.add_subplot()
    stroke = mech.crank_range is not None  # an open path: the working stroke is part of it
    if target is not None:
        drawn = target[:, :2] if stroke else np.vstack([target[:, :2], target[:1, :2]])
        ax.plot(*drawn.T, color="tab:blue", lw=2.5, alpha=0.6, label="target curve")
    label = "traced path (whole revolution)" if stroke else "traced path"
    ax.plot(*np.vstack([traced, traced[:1]]).T, color="tab:red", lw=1.2, label=label)
    if stroke:
        a, b = mech.crank_range
        working = joint_paths(mech, np.linspace(a, b, ANGLES))[mech.end_effector]
        degrees = f"{np.degrees(a):.0f} to {np.degrees(b):.0f} deg"
        ax.plot(*working.T, color="tab:green", lw=2.2, label=f"working stroke, crank {degrees}")
        ax.plot(*working[0], "o", color="tab:green", ms=7, label="stroke start")
        ax.plot(*working[-1], "s", color="tab:green", ms=7, label="stroke end")
    for joints in rigid_parts(mech)[1:]:
        if len(joints) > 2:  # a plate: shade its outline
            corners = mech.positions[list(joints)]
            centre = corners.mean(0)
            order = np.argsort(np.arctan2(*(corners - centre).T[::-1]))
            ax.fill(*corners[order].T, color="0.6", alpha=0.35, lw=0)
    for i, j in mech.links:
        ax.plot(*mech.positions[[i, j]].T, color="0.25", lw=2, solid_capstyle="round")
    moving = ~mech.fixed
    ax.plot(*mech.positions[moving].T, "o", color="white", mec="0.25", ms=6, ls="none")
    ax.plot(*mech.positions[mech.fixed].T, "^", color="0.25", ms=9, ls="none", label="ground")
    pivot, tip = mech.motor
    ax.plot(*mech.positions[[pivot, tip]].T, color="tab:orange", lw=3, label="crank")
    ax.plot(*mech.positions[mech.end_effector], "*", color="tab:red", ms=12, label="end effector")
    ax.set_aspect("equal")
    ax.set_xlabel(f"x ({mech.units})")
    ax.set_ylabel(f"y ({mech.units})")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"{mech.n_nodes}-joint linkage: target and traced curve")
    fig.tight_layout()
    with atomic_file(path, binary=True) as handle:
        fig.savefig(handle, format="png")
