"""Plots of a glitch report: the glitched spans marked on the joint angle curves (``clean --plots``).

* ``anatomy.png``: every anatomical angle of :mod:`.anatomy` (knees, elbows, hips,
  trunk) over time, its range of motion dashed, the spans found beyond it shaded red.
* ``<joint>.png`` for each joint with other glitches (at most :data:`MAX_JOINT_PLOTS`):
  the joint's speed (rotation speed in deg/s for rotational sources, position speed in
  m/s for joint positions) with each glitch's span shaded in its type's colour.

Uses the report plots' helpers (:mod:`physmocap.plots`): matplotlib's object API only,
PNGs written atomically without timestamps.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..motion import Motion
from ..plots import plot_directory, require_matplotlib, save_png, shade_spans
from .detect import Glitch, joint_angles_step

__all__ = ["write_glitch_plots", "MAX_JOINT_PLOTS"]

#: Most per-joint plots written (the joints with the most glitched frames first).
MAX_JOINT_PLOTS = 20
_KIND_COLORS = {
    "spike": "#d62728",
    "flip": "#9467bd",
    "discontinuity": "#8c564b",
    "frozen": "#1f77b4",
    "bone_stretch": "#ff7f0e",
    "gap": "#7f7f7f",
    "lr_swap": "#17becf",
    "anatomical": "#e377c2",
}


def _mask(glitches: list[Glitch], frames: int) -> np.ndarray:
    m = np.zeros(frames, dtype=bool)
    for g in glitches:
        m[g.start : g.end + 1] = True
    return m


def _anatomy_plot(figure_mod, motion: Motion, glitches: list[Glitch], path: Path) -> Path | None:
    from .anatomy import MOVEMENTS, motion_angles, movement_range
    from .detect import canonical_joints

    angles, _ = motion_angles(motion, canonical_joints(motion))
    shown = [m for m in MOVEMENTS if m.key in angles]
    if not shown:
        return None
    t = np.arange(motion.num_frames) / motion.fps
    cols = 2
    rows = (len(shown) + 1) // cols
    fig = figure_mod.Figure(figsize=(11, 2.0 * rows))
    axes = fig.subplots(rows, cols, squeeze=False, sharex=True)
    for ax, m in zip(axes.flat, shown):
        lo, hi = movement_range(m)
        ax.plot(t, angles[m.key], lw=0.8, color="#333333")
        ax.axhline(lo, ls="--", lw=0.6, color="#888888")
        ax.axhline(hi, ls="--", lw=0.6, color="#888888")
        mine = [g for g in glitches if g.movement.startswith(m.where + " ")]
        shade_spans(ax, _mask(mine, motion.num_frames), t, color="#d62728", alpha=0.3)
        ax.set_title(f"{m.key.replace('_', ' ')} ({m.plane})", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(shown):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("s", fontsize=7)
    fig.tight_layout()
    return save_png(fig, path)


def _joint_plot(figure_mod, motion: Motion, joint: str, glitches: list[Glitch], path: Path) -> Path:
    j = motion.skeleton.names.index(joint)
    t = np.arange(motion.num_frames) / motion.fps
    if motion.is_rotational:
        speed = joint_angles_step(np.asarray(motion.rotations)[:, j : j + 1])[:, 0] * motion.fps
        unit = "deg/s"
    else:
        p = np.asarray(motion.positions)[:, j]
        speed = np.r_[0.0, np.linalg.norm(np.diff(p, axis=0), axis=1) * motion.fps]
        unit = "m/s"
    fig = figure_mod.Figure(figsize=(11, 2.6))
    ax = fig.subplots()
    ax.plot(t, speed, lw=0.8, color="#333333")
    for kind in sorted({g.kind for g in glitches}):
        color = _KIND_COLORS.get(kind, "#2ca02c")
        shade_spans(ax, _mask([g for g in glitches if g.kind == kind], motion.num_frames), t, color=color, alpha=0.35)
        ax.plot([], [], lw=6, alpha=0.35, color=color, label=kind)
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title(f"{joint}: speed with the glitched spans", fontsize=9)
    ax.set_xlabel("s", fontsize=8)
    ax.set_ylabel(unit, fontsize=8)
    fig.tight_layout()
    return save_png(fig, path)


def write_glitch_plots(motion: Motion, glitches: list[Glitch] | tuple[Glitch, ...], directory: str | os.PathLike) -> list[Path]:
    """Write the plots described in the module docstring into ``directory`` (created if
    missing); returns the files written."""
    figure_mod = require_matplotlib()
    d = plot_directory(directory)
    glitches = list(glitches)
    written = []
    anatomy = _anatomy_plot(figure_mod, motion, [g for g in glitches if g.movement], d / "anatomy.png")
    if anatomy is not None:
        written.append(anatomy)
    by_joint: dict[str, list[Glitch]] = {}
    for g in glitches:
        if g.kind != "anatomical":
            by_joint.setdefault(g.joint, []).append(g)
    ranked = sorted(by_joint, key=lambda j: (-sum(g.end - g.start + 1 for g in by_joint[j]), j))
    used: set[str] = set()
    for joint in ranked[:MAX_JOINT_PLOTS]:
        stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", joint) or "joint"
        while stem in used or stem == "anatomy":
            stem += "_"
        used.add(stem)
        written.append(_joint_plot(figure_mod, motion, joint, by_joint[joint], d / f"{stem}.png"))
    return written
