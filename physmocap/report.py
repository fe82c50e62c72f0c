"""The quality report: source versus result, as a table and as JSON.

:func:`build_report` measures a character trajectory and, when given, the
source motion it came from with the definitions of :mod:`physmocap.metrics`
(``docs/metrics.md`` in the repository), side by side:

==========================  =====================  =====================
figure                      source                 result
==========================  =====================  =====================
foot skating                toe/ball + toe ends    contact sites
penetration                 lowest joint           lowest geom point
hovering (in contact)       above its floor        above ``z = 0``
joint limits, velocity,     (none: another         the character's
smoothness, tracking        skeleton)              joints and targets
==========================  =====================  =====================

:func:`format_report` renders the readable table, :func:`write_report_json`
writes the JSON (atomically, keys sorted, no NaN: missing figures are
``null``), :func:`emit_report` does both and the plots for the command line
(``physmocap report`` and ``physmocap retarget --report``).

JSON layout (``format`` is ``physmocap-report/1``)::

    {"format": ..., "character": {"name", "mjcf_path", "untracked_limbs"?},
     "source": {"path", "frames", "fps", "floor_m", "floor_slope"} | null,
     "contacts": {"origin": "detected" | CSV path,
                  "labels": {label: {"frames", "share", "segments"}}} | null,
     "metrics": {"source": {...} | null, "result": {...}}}

``character.untracked_limbs`` (present only for a character without some optional limb,
:data:`physmocap.models.character.OPTIONAL_LIMBS`) lists the limbs whose actor's motion is
not tracked, e.g. ``["left_arm", "right_arm"]`` for a legs-only robot; the fidelity figures
hold no segment of them.
``metrics.result`` holds :func:`physmocap.metrics.trajectory_metrics`,
``metrics.source`` :func:`physmocap.metrics.source_metrics`; units are in the
key names (``_cm_s``, ``_mm``, ``_deg``, ``_cm``) or rad, rad/s, rad/s^2,
rad/s^3 (joint speeds, smoothness).
"""

from __future__ import annotations

import inspect
import json
import math
import os
import sys
from pathlib import Path
from typing import IO, Any

import numpy as np

from .errors import InputError, OptionError, PhysmocapError
from .fileio import announce, atomic_open

__all__ = [
    "REPORT_FORMAT",
    "build_report",
    "format_report",
    "write_report_json",
    "emit_report",
    "load_trajectory",
    "root_scale",
    "tracking_targets",
]

REPORT_FORMAT = "physmocap-report/1"

#: Table rows: (label, dotted key into a metrics dict, unit, scale for display).
ROWS: tuple[tuple[str, str | None, str, float], ...] = (
    ("Foot skating in stance: mean", "skating.mean_cm_s", "cm/s", 1.0),
    ("  p95", "skating.p95_cm_s", "cm/s", 1.0),
    ("  max", "skating.max_cm_s", "cm/s", 1.0),
    ("  stance frames > 5 cm/s", "skating.share_over_5cm_s", "%", 100.0),
    ("  mean on labelled contact frames", "skating_labelled.mean_cm_s", "cm/s", 1.0),
    ("  p95 on labelled contact frames", "skating_labelled.p95_cm_s", "cm/s", 1.0),
    ("Penetration: max", "penetration.max_mm", "mm", 1.0),
    ("  mean (penetrating frames)", "penetration.mean_mm", "mm", 1.0),
    ("  frames > 1 mm", "penetration.share_over_1mm", "%", 100.0),
    ("Self-penetration (limbs, trunk): max", "self_penetration.max_mm", "mm", 1.0),
    ("  frames > 2 mm", "self_penetration.share_over_2mm", "%", 100.0),
    ("Hovering in contact: median", "hovering.median_mm", "mm", 1.0),
    ("  p95", "hovering.p95_mm", "mm", 1.0),
    ("Flat feet, highest contact site: median", "flat_feet.median_mm", "mm", 1.0),
    ("  p95", "flat_feet.p95_mm", "mm", 1.0),
    ("  frames > 1 cm up", "flat_feet.share_over_band", "%", 100.0),
    ("Joint-limit violations", "joint_limits.count", "", 1.0),
    ("  largest excess", "joint_limits.max_deg", "deg", 1.0),
    ("Velocity-limit violations", "velocity.count", "", 1.0),
    ("  peak joint speed", "velocity.peak_speed", "rad/s", 1.0),
    ("  peak speed / limit", "velocity.peak_ratio", "", 1.0),
    ("Mean |joint acceleration|", "smoothness.mean_abs_acc", "rad/s^2", 1.0),
    ("Mean |joint jerk|", "smoothness.mean_abs_jerk", "rad/s^3", 1.0),
    ("Tracking error: all joints, mean", "tracking.all_mean_cm", "cm", 1.0),
    ("  ankles/knees/wrists/elbows, mean", "tracking.key_joints_mean_cm", "cm", 1.0),
    ("  ankles/knees/wrists/elbows, p95", "tracking.key_joints_p95_cm", "cm", 1.0),
)


# ---------------------------------------------------------------------------
# Building
# ---------------------------------------------------------------------------


def _contacts_summary(contacts) -> dict | None:
    if contacts is None:
        return None
    labels = {}
    for name, lab in contacts.labels.items():
        lab = np.asarray(lab, dtype=bool)
        labels[name] = {
            "frames": int(lab.sum()),
            "share": float(lab.mean()) if lab.size else 0.0,
            "segments": len(contacts.segments(name)),
        }
    return {"origin": contacts.source, "labels": labels}


def build_report(traj, source_motion=None, contacts=None, joint_indices: dict[str, int] | None = None) -> dict:
    """Measure a trajectory (and its source) into a report dict (module docstring).

    Args:
        traj: The character's :class:`~physmocap.trajectory.Trajectory`
            (tracking errors need ``traj.targets``).
        source_motion: The motion it was retargeted from, over the same frames
            (after any ``--start/--end/--fps``), or None.
        contacts: Foot contact labels over the same frames; None takes
            ``traj.contacts`` if present, else detects them on the
            source.
        joint_indices: Canonical joint -> source joint index; None maps the
            source's names (:func:`physmocap.sources.profiles.map_skeleton`).
    """
    from . import metrics
    from .resources import portable_path

    F = traj.num_frames
    if contacts is None:
        contacts = traj.contacts
    source_info = None
    source_metrics = None
    if source_motion is not None:
        start = int(traj.source_start)
        if start and source_motion.num_frames == F + start and abs(source_motion.fps - traj.fps) < 1e-6 * traj.fps:
            # the whole clip, of which retarget skipped a reference first frame
            source_motion = source_motion.slice_frames(start, source_motion.num_frames)
        if source_motion.num_frames != F:
            raise OptionError(
                f"the source has {source_motion.num_frames} frames but the trajectory {F}; pass the "
                "source over the frames that were retargeted (--start, --fps)",
                path=source_motion.source,
            )
        if joint_indices is None:
            from .sources.profiles import map_skeleton

            joint_indices = dict(map_skeleton(source_motion.skeleton).indices)
        if contacts is None:
            from .ik.contacts import detect_contacts

            contacts = detect_contacts(source_motion, joint_indices)
        source_metrics = metrics.source_metrics(source_motion, joint_indices, contacts)
        floor = metrics._source_floor(source_motion, joint_indices, contacts)
        source_info = {
            "path": portable_path(source_motion.source, Path.cwd()),
            "frames": source_motion.num_frames,
            "fps": float(source_motion.fps),
            "floor_m": None if floor is None else float(floor.height),
            "floor_slope": None if floor is None else [float(floor.slope[0]), float(floor.slope[1])],
        }
    if contacts is not None and contacts.num_frames != F:
        raise OptionError(
            f"the contact labels cover {contacts.num_frames} frames but the trajectory has {F}",
            path=None if contacts.source == "detected" else contacts.source,
        )
    ch = traj.character
    fid = None
    if source_motion is not None and joint_indices is not None:
        from .metrics.fidelity import (
            actor_joint_positions, character_joint_positions, fidelity, figure_joints, with_pelvis_drift,
        )

        scale = root_scale(traj, source_motion, joint_indices, contacts)
        mine = character_joint_positions(traj, figure_joints())
        figures = fidelity(
            actor_joint_positions(source_motion, joint_indices, figure_joints()),
            mine,
            traj.fps,
            scale,
            model=ch.model,
            qpos=traj.qpos,
            velocity_limits=getattr(ch, "velocity_limits", None),
            velocity_groups=getattr(ch, "velocity_groups", ()),
        )
        # no drift for a trajectory read back without its targets
        fid = with_pelvis_drift(figures, traj, mine.get("pelvis")).as_dict()
    character = {
        "name": str(getattr(ch, "name", "")),
        "mjcf_path": portable_path(getattr(ch, "mjcf_path", ""), Path.cwd()),
    }
    from .models.character import untracked_limbs

    untracked = untracked_limbs(getattr(ch, "tracked", {}))
    if untracked:
        character["untracked_limbs"] = list(untracked)
    return {
        "format": REPORT_FORMAT,
        "fidelity": fid,
        "character": character,
        "source": source_info,
        "contacts": _contacts_summary(contacts),
        "metrics": {
            "source": source_metrics,
            "result": metrics.trajectory_metrics(traj, contacts),
        },
    }


# ---------------------------------------------------------------------------
# Table
# ---------------------------------------------------------------------------


def _get(d: dict | None, dotted: str):
    for part in dotted.split("."):
        if not isinstance(d, dict) or part not in d:
            return None
        d = d[part]
    return d


def _fmt(value, scale: float = 1.0) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)) and scale == 1.0:
        return str(int(value))
    v = float(value) * scale
    if not math.isfinite(v):
        return "-"
    a = abs(v)
    if a >= 1e5:
        return f"{v:.3g}"
    if a >= 100:
        return f"{v:.0f}"
    if a >= 10:
        return f"{v:.1f}"
    return f"{v:.2f}"


def _table(header: list[str], rows: list[list[str]], right: set[int]) -> list[str]:
    widths = [max(len(r[i]) for r in [header] + rows) for i in range(len(header))]

    def line(r: list[str]) -> str:
        return "  ".join(c.rjust(widths[i]) if i in right else c.ljust(widths[i]) for i, c in enumerate(r)).rstrip()

    return [line(header), "  ".join("-" * w for w in widths)] + [line(r) for r in rows]


def _fidelity_table(fid: dict | None) -> list[str]:
    """Rows of the fidelity section (character against actor, docs/metrics.md)."""
    if not fid:
        return []
    out = ["", "fidelity: the character against the actor"]
    rows = [
        [name, _fmt(v["median_deg"]), _fmt(v["p95_deg"]), _fmt(100 * v["share_over_45"])]
        for name, v in fid["segments"].items()
    ]
    out += _table(["segment direction", "median deg", "p95 deg", "% > 45 deg"], rows, {1, 2, 3})
    face, path, vz, sat = fid["facing"], fid["pelvis_path"], fid["pelvis_vertical_speed"], fid["velocity_saturation"]
    rows = [
        ["any segment > 45 deg", "% frames", _fmt(100 * fid["share_any_segment_over_45"])],
        ["facing error median / p95", "deg", f"{_fmt(face['median_deg'])} / {_fmt(face['p95_deg'])}"],
        ["pelvis path deviation mean / max", "cm", f"{_fmt(path['mean_cm'])} / {_fmt(path['max_cm'])}"],
    ]
    drift = fid.get("pelvis_drift") or {}
    if drift.get("mean_cm") is not None:
        rows.append(["pelvis drift from its target mean / max", "cm", f"{_fmt(drift['mean_cm'])} / {_fmt(drift['max_cm'])}"])
    rows += [
        [
            "pelvis vertical speed p99 (actor scaled)",
            "m/s",
            f"{_fmt(vz['character_p99'])} ({_fmt(vz['actor_p99_scaled'])})",
        ],
        ["velocity-cap saturation, any joint", "frames", f"{sat['frames']} ({_fmt(100 * sat['share'])} %)"],
        [
            "velocity-cap saturation, worst joint",
            "% frames",
            f"{_fmt(100 * sat.get('worst_joint_share', 0.0))} ({sat.get('worst_joint') or '-'})",
        ],
    ]
    jumps = fid.get("pops")
    if jumps:
        where = f", {jumps['worst_joint']} at frame {jumps['worst_frame']}" if jumps.get("worst_joint") else ""
        rows.append(["pops: joints jumping where the actor's do not", "frames",
                     f"{jumps['frames']} ({_fmt(100 * jumps['share'])} %)"])
        rows.append(["largest pop", "cm", f"{_fmt(jumps['worst_cm'])}{where}"])
    out += [""] + _table(["figure", "unit", "value"], rows, {2})
    return out


def format_report(report: dict) -> str:
    """A readable text table: metric, unit, source, result; then tracking per joint."""
    src = _get(report, "metrics.source")
    res = _get(report, "metrics.result")
    out = []
    ch = report.get("character") or {}
    title = f"physmocap report: {ch.get('name') or 'character'}"
    s = report.get("source")
    if s:
        title += f" from {s['path']} ({s['frames']} frames at {_fmt(s['fps'])} Hz)"
    elif res:
        title += f" ({res.get('frames')} frames at {_fmt(res.get('fps'))} Hz, no source)"
    out.append(title)
    if ch.get("untracked_limbs"):
        limbs = ", ".join(x.replace("_", " ") for x in ch["untracked_limbs"])
        out.append(f"not tracked: {limbs} (the character has none; no figure covers them)")
    if s and s.get("floor_m") is not None:
        slope = s.get("floor_slope") or [0.0, 0.0]
        out.append(
            f"source floor: {100 * s['floor_m']:.1f} cm, slope {100 * math.hypot(*slope):.2f} %"
        )
    c = report.get("contacts")
    if c:
        parts = [
            f"{name} {100 * v['share']:.0f} % ({v['segments']} contacts)" for name, v in c["labels"].items()
        ]
        out.append(f"contacts ({c['origin']}): " + ", ".join(parts))
    out.append("")
    rows = []
    for label, key, unit, scale in ROWS:
        a = _get(src, key) if key else None
        b = _get(res, key) if key else None
        if a is None and b is None:
            continue
        rows.append([label, unit, _fmt(a, scale), _fmt(b, scale)])
    out += _table(["metric", "unit", "source", "result"], rows, {2, 3})
    out += _fidelity_table(report.get("fidelity"))
    tr = _get(res, "tracking")
    if tr and tr.get("position_cm"):
        out += ["", "tracking error per joint (result)"]
        rows = []
        for name in tr["position_cm"]:
            p = tr["position_cm"][name]
            o = (tr.get("orientation_deg") or {}).get(name) or {}
            rows.append([name, _fmt(p["mean"]), _fmt(p["p95"]), _fmt(o.get("mean")), _fmt(o.get("p95"))])
        out += _table(["joint", "mean cm", "p95 cm", "mean deg", "p95 deg"], rows, {1, 2, 3, 4})
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------------------
# JSON
# ---------------------------------------------------------------------------


def _clean(x: Any) -> Any:
    """JSON-safe copy: numpy scalars and arrays to Python, non-finite floats to
    None, floats rounded to 6 significant digits (stable, readable)."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return [_clean(v) for v in x.tolist()]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        v = float(x)
        return float(f"{v:.6g}") if math.isfinite(v) else None
    if x is None or isinstance(x, str):
        return x
    return str(x)


def report_json(report: dict) -> str:
    """The report as JSON text: keys sorted, two-space indent, no NaN."""
    return json.dumps(_clean(report), sort_keys=True, indent=2, allow_nan=False) + "\n"


def write_report_json(report: dict, path: str | os.PathLike) -> Path:
    """Write the report as JSON, atomically (see :func:`report_json`)."""
    text = report_json(report)
    p = Path(path)
    with atomic_open(p, "w") as fh:
        fh.write(text)
    return p


# ---------------------------------------------------------------------------
# Command-line glue
# ---------------------------------------------------------------------------


def emit_report(
    traj,
    source_motion=None,
    contacts=None,
    *,
    json_path: str | os.PathLike | None = None,
    plots_dir: str | os.PathLike | None = None,
    joint_indices: dict[str, int] | None = None,
    stream: IO[str] | None = None,
    quiet: bool = False,
) -> dict:
    """Build the report, print its table on ``stream`` (stdout), write the JSON
    and the plots if asked; returns the report.  Paths are checked before any
    work is done.  ``quiet``: no table and no "wrote" lines.  For ``physmocap
    retarget --report``."""
    from .fileio import check_writable

    if json_path is not None:
        check_writable(json_path, "report")
    if plots_dir is not None:
        from .plots import require_matplotlib

        require_matplotlib()
        _check_plot_dir(plots_dir)
    report = build_report(traj, source_motion, contacts, joint_indices)
    if not quiet:
        (stream or sys.stdout).write(format_report(report))
    if json_path is not None:
        write_report_json(report, json_path)
        if not quiet:
            announce(f"wrote {json_path}")
    if plots_dir is not None:
        from .plots import write_plots

        if contacts is None:
            contacts = traj.contacts
        for p in write_plots(traj, source_motion, contacts, plots_dir, joint_indices=joint_indices):
            if not quiet:
                announce(f"wrote {p}")
    return report


def _check_plot_dir(path: str | os.PathLike) -> Path:
    from .fileio import check_output_dir

    return check_output_dir(path, "plot directory")


def load_trajectory(path: str | os.PathLike, character=None, map_path: str | os.PathLike | None = None):
    """Read a trajectory NPZ (``physmocap retarget --qpos``) back into a
    :class:`~physmocap.trajectory.Trajectory` (without targets).

    The character is loaded from the file's ``mjcf_path`` unless ``character``
    (a Character, a bundled name or an MJCF path) is given, with the mapping file the file
    records (``map_path``, the retarget's ``--map``) unless ``map_path`` is given or
    ``character`` names another model; a recorded mapping file that is missing is warned
    about and the model's default mapping used.
    """
    from .models import load_character
    from .trajectory import Trajectory

    p = Path(path)
    if not p.exists():
        raise InputError("trajectory file not found", path=p)
    if p.is_dir():
        raise InputError("is a directory, expected a trajectory .npz file", path=p)
    from .fileio import npz_array, npz_number, npz_text, read_npz
    from .sources import FPS_RANGE, MAX_DISTANCE

    data = read_npz(p, "a trajectory .npz file written by physmocap retarget --qpos")
    for key in ("qpos", "fps"):
        if key not in data:
            raise InputError(f"trajectory file has no {key!r} array (expected a physmocap retarget --qpos file)", path=p)
    qpos = npz_array(data["qpos"], "qpos", p, ("frames", "nq"))
    fps = npz_number(data["fps"], "fps", p, *FPS_RANGE)
    if qpos.shape[0] == 0:
        raise InputError(f"'qpos' must be a (frames, nq) array with frames, got shape {qpos.shape}", path=p)
    bad = ~np.all(np.isfinite(qpos) & (np.abs(qpos) <= MAX_DISTANCE), axis=1)
    if bad.any():
        raise InputError(
            f"'qpos' has values that are not finite or beyond {MAX_DISTANCE:g} (metres or radians)",
            path=p,
            frame=int(np.argmax(bad)),
        )
    if character is None or isinstance(character, (str, bytes)) or hasattr(character, "__fspath__"):
        from_file = character is None
        if character is None:
            if "mjcf_path" not in data:
                raise InputError("trajectory file names no character (mjcf_path); pass --character", path=p)
            from .resources import resolve_portable

            character = resolve_portable(npz_text(data["mjcf_path"], "mjcf_path", p), p.parent)
            bundled = _bundled_name(character)
            if Path(character).suffix and not Path(character).exists() and bundled:
                # an older file naming the bundled MJCF by another machine's absolute path
                from .errors import warn

                warn(f"{p}: the character's MJCF {character!r} is not here; using the bundled {bundled!r} "
                     "(pass --character to choose another)")
                character = bundled
            elif Path(character).suffix and not Path(character).exists():
                raise InputError(
                    f"the character's MJCF {character!r} named in the file does not exist; pass --character",
                    path=p,
                )
        if map_path is None:
            map_path = _stored_map(data, p, character, from_file)
        character = load_character(character, map_path)
    nq = character.model.nq
    if qpos.shape[1] != nq:
        raise InputError(
            f"'qpos' has {qpos.shape[1]} columns but the character {getattr(character, 'name', '')!r} has nq={nq}",
            path=p,
        )
    source = npz_text(data["source"], "source", p) if "source" in data else "<unknown>"
    if source and not source.startswith("<"):
        from .resources import resolve_portable

        source = resolve_portable(source, p.parent)  # stored relative to the file (or "example")
    traj = Trajectory(character=character, qpos=qpos, fps=fps, source=source)
    traj.targets = _stored_targets(data, qpos.shape[0], fps, p, character)
    if "source_start" in data:
        traj.source_start = int(npz_number(data["source_start"], "source_start", p, 0, 2**40, integer=True))
    return traj


def _stored_map(data: dict, path: Path, character, from_file: bool) -> str | None:
    """The mapping file the trajectory file records (``map_path``) for loading ``character``
    (its stored MJCF when ``from_file``, else one given): None when it records none (older
    files, or the default mapping), when ``character`` is another model than the one it
    stored, or, with a warning naming it and what is used instead, when the file is gone."""
    from .errors import warn
    from .fileio import npz_text
    from .models.character import character_file, default_map_file
    from .resources import mjcf_dir, resolve_portable

    stored = npz_text(data["map_path"], "map_path", path) if "map_path" in data else ""
    if not stored:
        return None

    try:
        mjcf = character_file(os.fsdecode(character))
        if not from_file and "mjcf_path" in data:
            recorded = character_file(resolve_portable(npz_text(data["mjcf_path"], "mjcf_path", path), path.parent))
            if mjcf.resolve() != recorded.resolve():
                return None  # another model than the one the mapping was written for
    except (PhysmocapError, OSError, ValueError):
        return None  # the character is refused (or compared) when it is loaded
    mapping = resolve_portable(stored, path.parent)
    if Path(mapping).is_file():
        return mapping
    default = default_map_file(mjcf)
    if default is None:
        instead = "the model's default mapping"
    elif default.resolve().is_relative_to(mjcf_dir().resolve()):
        instead = f"physmocap's bundled mapping {default.name}"  # not this installation's path
    else:
        instead = f"the mapping file {os.path.normpath(default)}"
    warn(f"{path}: the character's mapping file {os.path.normpath(mapping)} recorded in the file is not there; "
         f"using {instead} instead (pass --map to choose another)")
    return None


def _bundled_name(path: str) -> str | None:
    """The bundled character a stored MJCF path names (``.../assets/mjcf/humanoid.xml`` written
    on another machine), or None."""
    from .resources import mjcf_dir

    p = Path(path.replace("\\", "/"))
    if p.parent.name != "mjcf" or not p.suffix == ".xml":
        return None
    return p.stem if (mjcf_dir() / p.name).is_file() and p.stem in ("humanoid", "robot") else None


def _stored_targets(data: dict, frames: int, fps: float, path: Path, character=None):
    """The IK targets saved in a trajectory NPZ (``target_*`` arrays), or None."""
    from .ik.targets import Targets

    if "target_names" not in data:
        return None
    from .fileio import npz_array, npz_number, npz_strings

    names = tuple(npz_strings(data["target_names"], "target_names", path))
    N = len(names)
    if len(set(names)) != N:
        dup = sorted({n for n in names if names.count(n) > 1})
        raise InputError(f"'target_names' lists {', '.join(dup[:5])} more than once", path=path)
    tracked = getattr(character, "tracked", None)
    if tracked is not None:
        unknown = [n for n in names if n not in tracked]
        if unknown:
            raise InputError(
                f"'target_names' has {', '.join(unknown[:5])}, which the character "
                f"{getattr(character, 'name', '')!r} does not track",
                path=path,
            )
    missing = [k for k in ("target_positions", "target_orientations", "target_has_orientation", "target_valid")
               if k not in data]
    if missing:
        raise InputError(f"the stored IK targets lack {', '.join(missing)}", path=path)
    pos = npz_array(data["target_positions"], "target_positions", path, (frames, N, 3))
    quat = npz_array(data["target_orientations"], "target_orientations", path, (frames, N, 4))
    has_q = npz_array(data["target_has_orientation"], "target_has_orientation", path, (N,), kinds="b")
    valid = npz_array(data["target_valid"], "target_valid", path, (frames, N), kinds="b")
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(quat))):
        raise InputError("the stored IK targets have non-finite values", path=path)
    if "target_scale" not in data:  # written before the root scale was stored: the caller recomputes it
        return Targets(names, pos, quat, has_q, valid, fps=fps, info={SCALE_UNKNOWN: str(path)})
    scale = npz_number(data["target_scale"], "target_scale", path, *SCALE_RANGE)
    return Targets(names, pos, quat, has_q, valid, fps=fps, scale=scale)


#: ``Targets.info`` key set on stored targets whose root scale the file does not hold.
SCALE_UNKNOWN = "scale_unknown"
#: Root scales accepted in a trajectory NPZ (character leg length over the actor's).
SCALE_RANGE = (1e-3, 1e3)


def root_scale(traj, source_motion, joint_indices: dict[str, int], contacts=None) -> float:
    """The root scale the retarget used (the actor's speeds are scaled by it in the fidelity
    figures): the targets' own, 1 without targets.  A trajectory file written before the
    scale was stored has it recomputed as a default retarget computes it
    (:func:`tracking_targets`), with a warning: other retarget options may have set another."""
    targets = getattr(traj, "targets", None)
    if targets is None:
        return 1.0
    unknown = targets.info.pop(SCALE_UNKNOWN, None)
    if unknown is not None:
        from .errors import warn

        targets.scale = float(tracking_targets(source_motion, joint_indices, traj.character, contacts).scale)
        warn(f"{unknown}: the file stores no root scale (written by an older physmocap): the actor's scaled "
             f"speeds use a default retarget's, {targets.scale:.4g}; retarget again for exact figures")
    return float(targets.scale)


def tracking_targets(motion, joint_indices: dict[str, int], character, contacts=None):
    """Rebuild the IK targets of a retargeted clip (default target options),
    so a report on a saved trajectory can measure tracking errors.

    These are :func:`~physmocap.ik.targets.build_targets`' targets; any later
    adjustment the retargeter makes to them (options, planting) is not
    reproduced, so figures can differ slightly from ``retarget --report``.
    """
    from .ik.targets import build_targets

    kwargs = {}
    if contacts is not None and contacts.floor is not None and "floor" in inspect.signature(build_targets).parameters:
        kwargs["floor"] = contacts.floor
    return build_targets(motion, joint_indices, character, **kwargs)
