"""PNG plots for the quality report (needs the ``plot`` extra: matplotlib).

:func:`write_plots` writes into a directory:

* ``contacts.png``: contact timelines per foot (heel and toe labels).
* ``feet.png``: per foot, the height of the character's contact sites (and of
  the source's toe points above its estimated floor) and their horizontal
  speed, with the frames the foot is in contact shaded.
* ``joints.png``: every limited hinge/slide joint's value as a percentage of
  its range (0 % its lower limit, 100 % its upper one), grouped by body part,
  out-of-range samples in red.

matplotlib is imported only here, through :func:`require_matplotlib`, and
only its object-oriented API is used (no pyplot, no global backend change).
Files are written atomically; the PNGs carry no timestamp or software tag.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .errors import OptionError
from .fileio import atomic_open

__all__ = ["require_matplotlib", "write_plots", "plot_directory", "save_png", "shade_spans", "PLOT_FILES"]

PLOT_FILES = ("contacts.png", "feet.png", "joints.png")
_COLORS = {"heel": "#d62728", "toe": "#1f77b4"}


def require_matplotlib():
    """The ``matplotlib.figure`` module, or a clear error naming the extra to install."""
    try:
        import matplotlib  # noqa: F401
        from matplotlib import figure
    except ImportError:
        raise OptionError(
            "plots need matplotlib, which is not installed: pip install 'physmocap[plot]'"
        ) from None
    return figure


def plot_directory(directory: str | os.PathLike) -> Path:
    """``directory`` as a :class:`Path`, created if missing (not its parents); a clear
    :class:`OutputError` if it is a file or cannot be made."""
    from .fileio import make_output_dir

    return make_output_dir(directory, "plot directory")


def save_png(fig, path: Path) -> Path:
    """Write a figure as a PNG, atomically, with no timestamp or software tag."""
    return _save(fig, path)


def _save(fig, path: Path) -> Path:
    with atomic_open(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=80, metadata={"Software": None})
    return path


def shade_spans(ax, mask: np.ndarray, t: np.ndarray, color: str = "#2ca02c", alpha: float = 0.15) -> None:
    """Shade the runs of ``mask`` over times ``t`` on axes ``ax``."""
    _shade(ax, mask, t, color, alpha)


def _shade(ax, mask: np.ndarray, t: np.ndarray, color: str = "#2ca02c", alpha: float = 0.15) -> None:
    m = np.concatenate([[False], np.asarray(mask, bool), [False]]).astype(np.int8)
    d = np.flatnonzero(np.diff(m))
    dt = (t[1] - t[0]) if t.size > 1 else 1.0
    for a, b in zip(d[::2], d[1::2]):
        ax.axvspan(t[a] - dt / 2, t[b - 1] + dt / 2, color=color, alpha=alpha, lw=0)


def _contacts_plot(figure_mod, contacts, fps: float, path: Path) -> Path:
    fig = figure_mod.Figure(figsize=(12, 3.2))
    ax = fig.add_subplot(1, 1, 1)
    names = list(contacts.labels)
    for row, name in enumerate(names):
        segs = [(a / fps, (b - a) / fps) for a, b in contacts.segments(name)]
        part = "heel" if name.endswith("heel") else "toe"
        ax.broken_barh(segs, (row - 0.35, 0.7), color=_COLORS[part])
    ax.set_yticks(range(len(names)))
    ax.set_yticklabels(names)
    ax.set_ylim(-0.6, len(names) - 0.4)
    ax.invert_yaxis()
    ax.set_xlim(0, max(contacts.num_frames - 1, 1) / fps)
    ax.set_xlabel("time (s)")
    ax.set_title(f"foot contacts ({contacts.source})")
    ax.grid(True, axis="x", alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def _feet_plot(figure_mod, traj, source_motion, contacts, joint_indices, path: Path) -> Path:
    from .metrics import horizontal_speeds

    fps = traj.fps
    t = np.arange(traj.num_frames) / fps
    ch = traj.character.contacts
    sides = [s for s in ("left", "right") if s in ch]
    src_pts = {}
    if source_motion is not None and joint_indices is not None:
        world = source_motion.world_positions()
        floor = contacts.floor if contacts is not None else None
        for side in sides:
            for j in ("toe", "toe_end"):
                name = f"{side}_{j}"
                if name in joint_indices:
                    x = world[:, joint_indices[name]]
                    z = floor.heights(x) if floor is not None else x[:, 2] - source_motion.floor_height()
                    src_pts[name] = (z, horizontal_speeds(x[:, None], source_motion.fps)[:, 0])
    fig = figure_mod.Figure(figsize=(12, 2.6 * 2 * len(sides)))
    axes = [fig.add_subplot(2 * len(sides), 1, i + 1) for i in range(2 * len(sides))]
    for k, side in enumerate(sides):
        sites = list(ch[side])
        pos = traj.site_positions(sites)
        speed = horizontal_speeds(pos, fps)
        ah, av = axes[2 * k], axes[2 * k + 1]
        for i, s in enumerate(sites):
            ah.plot(t, 100 * pos[:, i, 2], lw=1, label=f"{s} (result)")
            av.plot(t, 100 * speed[:, i], lw=1, label=s)
        for name, (z, v) in src_pts.items():
            if name.startswith(side + "_"):
                ah.plot(t, 100 * z, lw=0.8, ls="--", label=f"{name} (source)")
        if contacts is not None:
            foot = contacts.foot(side)
            _shade(ah, foot, t)
            _shade(av, foot, t)
        ah.axhline(1.0, color="k", lw=0.6, ls=":")
        av.axhline(5.0, color="k", lw=0.6, ls=":")
        ah.set_ylabel(f"{side} height (cm)")
        av.set_ylabel(f"{side} speed (cm/s)")
        top = np.nanpercentile(100 * pos[..., 2], 99) if pos.size else 1.0
        ah.set_ylim(-2, max(5.0, min(60.0, float(top) * 1.1)))
        vtop = np.nanpercentile(100 * speed, 90) if speed.size else 1.0
        av.set_ylim(0, max(10.0, min(500.0, float(vtop) * 1.5)))
        ah.legend(fontsize=7, loc="upper right", ncol=2)
        for a in (ah, av):
            a.grid(True, alpha=0.3)
            a.set_xlim(t[0], t[-1] if t.size > 1 else 1.0)
    axes[-1].set_xlabel("time (s); shaded: foot labelled in contact; dotted: 1 cm stance / 5 cm/s")
    fig.tight_layout()
    return _save(fig, path)


_LEG = ("hip", "knee", "ankle", "toe", "foot", "leg", "thigh", "shin")
_ARM = ("clavicle", "shoulder", "elbow", "forearm", "wrist", "arm", "hand")


def _joint_group(name: str) -> str:
    n = name.lower()
    side = "left " if n.startswith(("left", "l_", "lft")) else "right " if n.startswith(("right", "r_", "rgt")) else ""
    if side and any(w in n for w in _LEG):
        return side + "leg"
    if side and any(w in n for w in _ARM):
        return side + "arm"
    return "torso, neck, head" if not side else side + "other"


def _joints_plot(figure_mod, traj, path: Path) -> Path:
    import mujoco

    model = traj.model
    kinds = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    joints = [j for j in range(model.njnt) if int(model.jnt_type[j]) in kinds and model.jnt_limited[j]]
    groups: dict[str, list[int]] = {}
    for j in joints:
        groups.setdefault(_joint_group(model.joint(j).name), []).append(j)
    order = sorted(groups, key=lambda g: (g.split()[-1] != "head", g))
    n = max(len(order), 1)
    fig = figure_mod.Figure(figsize=(14, 2.4 * n))
    t = np.arange(traj.num_frames) / traj.fps
    for k, g in enumerate(order):
        ax = fig.add_subplot(n, 1, k + 1)
        for j in groups[g]:
            q = traj.qpos[:, model.jnt_qposadr[j]]
            lo, hi = model.jnt_range[j]
            u = 100.0 * (q - lo) / max(hi - lo, 1e-12)
            ax.plot(t, u, lw=0.8, label=model.joint(j).name)
            out = (q < lo - 1e-6) | (q > hi + 1e-6)
            if out.any():
                ax.plot(t[out], u[out], ".", ms=3, color="#d62728")
        ax.axhline(0.0, color="k", lw=0.8, ls="--")
        ax.axhline(100.0, color="k", lw=0.8, ls="--")
        ax.set_ylim(-10, 110)
        ax.set_xlim(t[0], t[-1] if t.size > 1 else 1.0)
        ax.set_ylabel("% of range")
        ax.set_title(g, fontsize=9)
        ax.legend(fontsize=6, loc="center left", bbox_to_anchor=(1.0, 0.5), ncol=1 + len(groups[g]) // 8)
        ax.grid(True, alpha=0.3)
    fig.axes[-1].set_xlabel("time (s); joint angle within its limits (0 % lower, 100 % upper); red: outside")
    fig.subplots_adjust(left=0.05, right=0.72, bottom=0.5 / n / 2.4, top=1 - 0.35 / n / 2.4, hspace=0.45)
    return _save(fig, path)


def write_plots(traj, source_motion=None, contacts=None, directory: str | os.PathLike = ".", joint_indices=None) -> list[Path]:
    """Write the report's PNG plots into ``directory`` (created if missing).

    Args:
        traj: The character's trajectory.
        source_motion: The source over the same frames (its toe heights are
            drawn when ``joint_indices`` is given or can be mapped), or None.
        contacts: Foot contact labels (timelines and shading), or None.
        directory: Output directory.
        joint_indices: Canonical joint -> source joint index.

    Returns:
        The files written.
    """
    figure_mod = require_matplotlib()
    d = plot_directory(directory)
    if source_motion is not None and joint_indices is None:
        from .sources.profiles import map_skeleton

        joint_indices = dict(map_skeleton(source_motion.skeleton).indices)
    written = []
    if contacts is not None:
        written.append(_contacts_plot(figure_mod, contacts, traj.fps, d / "contacts.png"))
    written.append(_feet_plot(figure_mod, traj, source_motion, contacts, joint_indices, d / "feet.png"))
    written.append(_joints_plot(figure_mod, traj, d / "joints.png"))
    return written
