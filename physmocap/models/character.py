"""A character: an MJCF model plus what the retargeter needs to know about it.

:func:`load_character` loads the default humanoid, a bundled character by name
(``"humanoid"``, ``"robot"``) or any MJCF file with its mapping file, and
computes, in the rest pose standing on the floor (z = 0):

* the world position of every mapped canonical joint (:meth:`Character.rest_positions`);
* segment lengths ``|x_child - x_parent|`` between each mapped canonical joint
  and its nearest mapped canonical ancestor (:func:`physmocap.canonical.canonical_parent`);
* the hip height (mean height of the two hip joint centres), the standing
  height (top of the highest geom), the total mass;
* joint ranges (radians / metres) and speed limits (rad/s / m/s) of every
  hinge and slide joint.
"""

from __future__ import annotations

import contextlib
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Hashable, Iterator

import mujoco
import numpy as np

from ..canonical import REQUIRED_JOINTS, canonical_parent
from ..errors import InputError, MappingError, warn
from ..resources import mjcf_dir
from ..rotations import Rotation, quat_mul, wxyz_to_xyzw, xyzw_to_wxyz
from . import rom
from .geometry import character_geoms, highest_z, lowest_z
from .mapping import AXES, Mapping, TrackedFrame, implicit_mapping, read_mapping
from .hinge_groups import hinge_groups
from .velocity import FALLBACK_DEG_S, human_velocity_limit

__all__ = [
    "Character",
    "TrackedFrame",
    "load_character",
    "character_file",
    "default_map_file",
    "bundled_characters",
    "DEFAULT_CHARACTER",
    "CHARACTER_REQUIRED",
    "OPTIONAL_LIMBS",
    "untracked_limbs",
]

#: Name of the default character.
DEFAULT_CHARACTER = "humanoid"

_LIMITED = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))

#: Limbs a character may lack, each side on its own: limb -> (the joints that make it, all
#: mapped or none; the joints that hang on it, mapped only with it).  A robot without arms
#: (a legs-only biped) is a character whose arms are not tracked; legs are required (the
#: retargeter plants feet).
OPTIONAL_LIMBS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    f"{side}_arm": ((f"{side}_shoulder", f"{side}_elbow"), (f"{side}_clavicle", f"{side}_wrist", f"{side}_hand_end"))
    for side in ("left", "right")
}

#: Canonical joints a character may leave unmapped although a source skeleton must provide
#: them (:data:`physmocap.canonical.REQUIRED_JOINTS`): a robot may lack a neck, wrists, or
#: whole arms (:data:`OPTIONAL_LIMBS`).
CHARACTER_OPTIONAL: tuple[str, ...] = ("neck",) + tuple(
    j for core, hung in OPTIONAL_LIMBS.values() for j in core + hung
)
CHARACTER_REQUIRED: tuple[str, ...] = tuple(j for j in REQUIRED_JOINTS if j not in CHARACTER_OPTIONAL)


@dataclass
class Character:
    """An MJCF character ready for retargeting.  Units: metres, radians, kg, seconds.

    Attributes:
        name: character name (mapping ``[character] name`` or the MJCF stem).
        mjcf_path: the MJCF file loaded.
        map_path: the mapping file used, or None for an implicit mapping.
        model: the compiled model; its ``jnt_range`` / ``jnt_limited`` agree
            with :attr:`joint_limits` (mapping overrides are applied to it).
        root_joint: name of the free joint of the floating base.
        tracked: canonical joint -> :class:`TrackedFrame` (site or body); mapped joints only.
        contacts: ``"left"`` / ``"right"`` -> foot contact site names, heel to toe.
        rest_qpos: ``(nq,)`` rest pose: standing on z = 0, facing +X, Z up.
        joint_limits: hinge/slide joint -> ``(lo, hi)`` rad (m for slides);
            ``(-inf, inf)`` for a joint without a range.
        velocity_limits: hinge/slide joint -> speed limit, rad/s (m/s), positive.
        velocity_groups: hinges that turn one body about one point and whose limits are
            human joint speeds (:func:`~physmocap.models.hinge_groups.hinge_groups`): their
            limits bound the body's angular speed along each hinge's axis, not the hinge's
            rate (which grows without bound at a gimbal lock).
        segment_lengths: ``(parent canonical, child canonical)`` -> metres in the
            rest pose, parent = nearest mapped canonical ancestor.
        hip_height: mean height of the hip joint centres in the rest pose, m.
        height: standing height (top of the highest geom in the rest pose), m.
        total_mass: kg.
        mapping_proposed: True when no mapping file was found and the mapping is the
            one :func:`~physmocap.models.propose.propose_mapping` proposed.
        rest_pose: Where the rest pose comes from, in words (``keyframe 'home'``, ``zero
            pose``; ``, 2 joints set by [rest.joints]``).
    """

    name: str
    mjcf_path: Path
    map_path: Path | None
    model: mujoco.MjModel
    root_joint: str
    tracked: dict[str, TrackedFrame]
    contacts: dict[str, tuple[str, ...]]
    rest_qpos: np.ndarray
    joint_limits: dict[str, tuple[float, float]]
    velocity_limits: dict[str, float]
    segment_lengths: dict[tuple[str, str], float]
    hip_height: float
    height: float
    total_mass: float
    mapping_proposed: bool = False
    velocity_groups: tuple[tuple[str, ...], ...] = ()
    rest_pose: str = ""
    _rest: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    #: What is worked out from the character alone once and kept (:meth:`derived`); a copy
    #: made with ``dataclasses.replace`` starts afresh.
    _derived: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def rest_positions(self) -> dict[str, np.ndarray]:
        """Canonical joint -> world position (m) in the rest pose (copies)."""
        return {k: v.copy() for k, v in self._rest.items()}

    def rest_data(self) -> mujoco.MjData:
        """A new ``MjData`` posed in the rest pose (``rest_qpos``), kinematics computed."""
        data = mujoco.MjData(self.model)
        data.qpos[:] = self.rest_qpos
        mujoco.mj_kinematics(self.model, data)
        return data

    def derived(self, key: Hashable, make: Callable[[], Any]) -> Any:
        """``make()``, computed once per character and key and kept (a quantity of the
        character alone, e.g. its trunk's reach: a stream prepares it before its first frame)."""
        if key not in self._derived:
            self._derived[key] = make()
        return self._derived[key]

    def frame_id(self, canonical: str) -> int:
        """MuJoCo id of the site or body tracked for ``canonical``."""
        return self.tracked[canonical].object_id(self.model)

    def hinge_names(self) -> list[str]:
        """Names of the hinge and slide joints, in model order."""
        return list(self.joint_limits)


def bundled_characters() -> dict[str, Path]:
    """Bundled characters: name -> MJCF path (``assets/mjcf/<name>.xml`` with a mapping file)."""
    d = mjcf_dir()
    return {p.name[: -len(".map.toml")]: d / (p.name[: -len(".map.toml")] + ".xml")
            for p in sorted(d.glob("*.map.toml"))
            if (d / (p.name[: -len(".map.toml")] + ".xml")).exists()}


def character_file(path: str | os.PathLike | None) -> Path:
    """The MJCF file ``load_character(path)`` reads: the default humanoid for None, a
    bundled character by name, else ``path`` itself (not checked to exist); InputError for
    a name that is no bundled character."""
    return _resolve(path)


def default_map_file(mjcf: str | os.PathLike) -> Path | None:
    """The mapping file ``load_character(mjcf)`` reads without a given one: ``NAME.map.toml``
    beside the model (or its scene's), else one bundled with physmocap for that model's file
    name; None where there is none (the model's own names, or a proposed mapping)."""
    return _find_map(Path(mjcf), None)


def _resolve(path: str | os.PathLike | None) -> Path:
    if path is None:
        return mjcf_dir() / f"{DEFAULT_CHARACTER}.xml"
    s = os.fspath(path)
    p = Path(s)
    if not p.suffix and os.sep not in s and "/" not in s and not p.exists():
        bundled = bundled_characters()
        if s in bundled:
            return bundled[s]
        raise InputError(
            f"no such character; bundled characters are {', '.join(bundled)}, or give an MJCF path",
            path=s,
        )
    return p


def _load_model(path: Path, mp: Mapping | None = None) -> mujoco.MjModel:
    """Compile the MJCF (:func:`_compile_model`) and check what it holds: names that are
    UTF-8 text, and bodies, sites and geoms at finite places within 1 km at the rest pose."""
    model = _compile_model(path, mp)
    names = bytes(model.names)
    try:
        names.decode("utf-8")
    except UnicodeDecodeError as exc:
        lo, hi = names.rfind(b"\0", 0, exc.start) + 1, names.find(b"\0", exc.start)
        bad = names[lo : hi if hi >= 0 else None]
        raise InputError(f"the name {bad!r} is not UTF-8 text", path=path) from None
    data = mujoco.MjData(model)
    with np.errstate(all="ignore"):
        mujoco.mj_kinematics(model, data)
        for what, arr, name_of in (("body", data.xpos, model.body), ("site", data.site_xpos, model.site),
                                   ("geom", data.geom_xpos, model.geom)):
            bad = ~np.all(np.isfinite(arr) & (np.abs(arr) < 1000.0), axis=1)
            if bad.any():
                i = int(np.argmax(bad))
                raise InputError(
                    f"{what} {name_of(i).name or i!r} is not at a finite place within 1 km at the rest pose "
                    f"({arr[i].tolist()})",
                    path=path,
                )
    return model


@contextlib.contextmanager
def mujoco_warnings(path: Path) -> Iterator[None]:
    """MuJoCo's warnings while ``path`` loads (its own handler prints them on stdout and
    writes ``MUJOCO_LOG.TXT`` into the working folder): collected, then given as physmocap
    warnings naming the file (stderr) once it has loaded; dropped when it does not (the
    error says what is wrong)."""
    heard: list[str] = []
    before = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda message: heard.append(" ".join(str(message).split())))
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(before)
    for message in heard:
        warn(f"{path}: MuJoCo: {message}")


def read_mjcf(path: Path, spec: bool = False) -> mujoco.MjModel | mujoco.MjSpec:
    """The MJCF at ``path`` compiled (or its ``MjSpec``, ``spec``, to add to before
    compiling): one clear error for a missing file, a folder or a file MuJoCo refuses;
    MuJoCo's warnings on stderr (:func:`mujoco_warnings`)."""
    if not path.exists():
        raise InputError("MJCF file not found", path=path)
    if path.is_dir():
        raise InputError("is a directory, expected an MJCF file", path=path)
    try:
        with mujoco_warnings(path):
            return mujoco.MjSpec.from_file(os.fspath(path)) if spec else mujoco.MjModel.from_xml_path(os.fspath(path))
    except (ValueError, OSError) as exc:
        msg = " ".join(str(exc).split())
        raise InputError(f"MuJoCo cannot load this MJCF: {msg}", path=path) from None


def _compile_model(path: Path, mp: Mapping | None = None) -> mujoco.MjModel:
    """Compile the MJCF; with a mapping's ``[sites]``, add those sites first (MjSpec)."""
    if mp is None or not mp.sites:
        return read_mjcf(path)
    spec = read_mjcf(path, spec=True)
    for name, (body_name, pos) in mp.sites.items():
        body = spec.body(body_name)
        if body is None:
            raise mp.error(f"the model has no body {body_name!r}", "sites", name)
        if spec.site(name) is not None:
            raise mp.error(f"the model already has a site {name!r}", "sites", name)
        body.add_site(name=name, pos=list(pos))
    try:
        with mujoco_warnings(path):
            return spec.compile()
    except (ValueError, OSError) as exc:
        msg = " ".join(str(exc).split())
        raise InputError(f"MuJoCo cannot compile this MJCF with the added sites: {msg}", path=path) from None


def _find_map(mjcf: Path, map_path: str | os.PathLike | None) -> Path | None:
    if map_path is not None:
        return Path(map_path)
    candidates = [mjcf.with_name(mjcf.stem + ".map.toml")]
    if mjcf.stem == "scene":  # the scene that includes the default humanoid
        candidates.append(mjcf.with_name(f"{DEFAULT_CHARACTER}.map.toml"))
    elif mjcf.stem.startswith("scene_"):  # scene_<name>.xml includes <name>.xml
        candidates.append(mjcf.with_name(mjcf.stem[len("scene_"):] + ".map.toml"))
    # mapping files bundled for known robot models, found by the model's file name
    from ..resources import mjcf_dir

    candidates.append(mjcf_dir() / "robots" / f"{mjcf.stem}.map.toml")
    for c in candidates:
        if c.exists():
            return c
    return None


def _resolve_frames(mp: Mapping, model: mujoco.MjModel) -> dict[str, TrackedFrame]:
    out = {}
    for canon, tf in mp.joints.items():
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, tf.name)
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, tf.name)
        if tf.kind == "site" and site < 0:
            raise mp.error(f"the model has no site {tf.name!r}", "joints", canon)
        if tf.kind == "body" and body < 0:
            raise mp.error(f"the model has no body {tf.name!r}", "joints", canon)
        if tf.kind == "auto":
            if site >= 0:
                tf = TrackedFrame("site", tf.name)
            elif body >= 0:
                tf = TrackedFrame("body", tf.name)
            else:
                raise mp.error(f"the model has no site or body {tf.name!r}", "joints", canon)
        if tf.kind == "body" and body == 0:
            raise mp.error("the world body cannot be tracked", "joints", canon)
        out[canon] = tf
    return out


def _joint_id(mp: Mapping, model: mujoco.MjModel, section: str, name: str) -> int:
    j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
    if j < 0:
        raise mp.error(f"the model has no joint {name!r}", section, name)
    return j


def _is_angular(model: mujoco.MjModel, j: int) -> bool:
    return int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE)


def _root_joint(model: mujoco.MjModel, where: Path) -> int:
    free = [j for j in range(model.njnt) if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE)]
    if len(free) != 1:
        raise MappingError(
            f"expected exactly one free joint (the floating base), found {len(free)}", path=where
        )
    return free[0]


def _up_forward_rotation(up: str, forward: str) -> np.ndarray:
    """Rotation (3x3) taking the model's ``up`` to +Z and its ``forward`` to +X."""
    u = np.array(AXES[up])
    f = np.array(AXES[forward])
    src = np.stack([f, np.cross(u, f), u], axis=1)  # columns: forward, left, up
    return src.T  # maps f -> X, left -> Y, u -> Z


def _proposed_mapping(mjcf: Path):
    """The mapping :func:`~physmocap.models.propose.propose_mapping` proposes for a model
    that has no mapping file, said in one warning; else why it proposes none (a string:
    the caller reports it with what is missing)."""
    from ..errors import InputError, warn
    from .mapping import mapping_from_text
    from .propose import propose_mapping

    try:
        proposal = propose_mapping(mjcf)
    except (MappingError, InputError) as exc:
        return getattr(exc, "message", None) or str(exc)
    untracked = untracked_limbs(proposal.joints)
    lacks = f"; {_limbs_phrase(untracked)}: the actor's are not tracked" if untracked else ""
    warn(
        f"{mjcf}: no mapping file found: using the mapping `physmocap character init` proposes "
        f"({len(proposal.joints)} joints{lacks}; run `physmocap character init {mjcf} -o "
        f"{mjcf.with_name(mjcf.stem + '.map.toml')}` to see, edit and keep it)"
    )
    return mapping_from_text(proposal.to_toml(), mjcf.with_name(f"{mjcf.stem}.map.toml (proposed)"))


def load_character(
    path: str | os.PathLike | None = None,
    map_path: str | os.PathLike | None = None,
    *,
    range_policy: str | None = None,
) -> Character:
    """Load a character and compute its description.

    Args:
        path: ``None`` for the default humanoid, a bundled name (``"humanoid"``,
            ``"robot"``), or an MJCF file.
        map_path: mapping file; default ``<stem>.map.toml`` beside the MJCF.
            A model without one maps its sites named like canonical joints, or,
            if that leaves required joints or the arms unmapped, takes the mapping
            :func:`~physmocap.models.propose.propose_mapping` proposes (with a warning).
        range_policy: ``"default"`` or ``"strict"``: for joints in the
            range-of-motion table (:mod:`physmocap.models.rom`), replace their
            ranges with the table's under this policy.  Overrides the mapping's
            ``range_policy``.

    Raises:
        InputError: the MJCF or the mapping file cannot be read.
        MappingError: the mapping names a missing site/body/joint, leaves a
            required canonical joint unmapped, maps part of an optional limb
            (:data:`OPTIONAL_LIMBS`), or a joint lacks required limits.
    """
    mjcf = _resolve(path)
    mp_file = _find_map(mjcf, map_path)
    if mp_file is not None:
        mp = read_mapping(mp_file)
        model = _load_model(mjcf, mp)
    else:
        model = _load_model(mjcf)
        mp = implicit_mapping(model)
    why = None  # why no mapping could be proposed
    wanted = CHARACTER_REQUIRED + tuple(j for core, _ in OPTIONAL_LIMBS.values() for j in core)
    if mp_file is None and any(j not in _resolve_frames(mp, model) for j in wanted):
        proposed = _proposed_mapping(mjcf)
        if isinstance(proposed, str):
            why = proposed
        else:
            mp = proposed
            model = _load_model(mjcf, mp)
    where = mp_file if mp_file is not None else mjcf
    tracked = _resolve_frames(mp, model)
    missing = [j for j in CHARACTER_REQUIRED if j not in tracked]
    if missing:
        hint = "[joints]" if mp_file is not None else "no mapping file found (give --map or write <stem>.map.toml);"
        reason = f" (no mapping could be proposed: {why})" if why else ""
        raise MappingError(
            f"{hint} required canonical joint(s) not mapped: {', '.join(missing)}{reason}", path=where
        )
    _check_limbs(tracked, mp, where)
    for side, sites in mp.contacts.items():
        for s in sites:
            if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) < 0:
                raise mp.error(f"the model has no site {s!r}", "contacts", side)
    if not mp.contacts and all(f"{side}_ankle" in tracked for side in ("left", "right")):
        model, tracked = _add_foot_contacts(mjcf, mp, model, tracked, where)

    root = _root_joint(model, mjcf)

    # -- joint ranges ----------------------------------------------------------
    policy = range_policy or mp.range_policy
    if policy is not None and policy not in rom.POLICIES:
        raise MappingError(f"unknown range policy {policy!r}; expected one of {rom.POLICIES}", path=where)
    hinge_ids = [j for j in range(model.njnt) if int(model.jnt_type[j]) in _LIMITED]
    if policy is not None:
        for j in hinge_ids:
            try:
                lo, hi = rom.joint_range_deg(model.joint(j).name, policy)
            except KeyError:
                continue
            model.jnt_range[j] = (math.radians(lo), math.radians(hi))
            model.jnt_limited[j] = 1
    for jn, (lo, hi) in mp.joint_limits.items():
        j = _joint_id(mp, model, "joint_limits", jn)
        if int(model.jnt_type[j]) not in _LIMITED:
            raise mp.error("only hinge and slide joints take [lo, hi] limits", "joint_limits", jn)
        k = math.pi / 180.0 if _is_angular(model, j) else 1.0
        model.jnt_range[j] = (lo * k, hi * k)
        model.jnt_limited[j] = 1
    required = mp.require_limits
    if isinstance(required, tuple):
        for jn in required:
            j = _joint_id(mp, model, "character", jn)
            if not model.jnt_limited[j]:
                raise MappingError(
                    f"joint {jn!r} has no range, but the mapping requires one "
                    "(add range=\"lo hi\" in the MJCF or [joint_limits] in the mapping)",
                    path=mjcf,
                )
    elif required:
        for j in hinge_ids:
            if not model.jnt_limited[j]:
                raise MappingError(
                    f"joint {model.joint(j).name!r} has no range, but the mapping "
                    f"({where.name}) requires limits on every hinge "
                    "(add range=\"lo hi\" in the MJCF or [joint_limits] in the mapping)",
                    path=mjcf,
                )
    joint_limits: dict[str, tuple[float, float]] = {}
    for j in hinge_ids:
        name = model.joint(j).name
        if model.jnt_limited[j]:
            joint_limits[name] = (float(model.jnt_range[j][0]), float(model.jnt_range[j][1]))
        else:
            joint_limits[name] = (-math.inf, math.inf)

    # -- speed limits ----------------------------------------------------------
    for jn in mp.velocity_limits:
        if jn != "default":
            _joint_id(mp, model, "velocity_limits", jn)
    default_speed = mp.velocity_limits.get("default", FALLBACK_DEG_S)
    velocity_limits: dict[str, float] = {}
    anatomical: set[str] = set()  # limits that are a human joint's angular speed
    for j in hinge_ids:
        name = model.joint(j).name
        k = math.pi / 180.0 if _is_angular(model, j) else 1.0
        if name in mp.velocity_limits:
            v = mp.velocity_limits[name] * k
        else:
            human = human_velocity_limit(name) if _is_angular(model, j) else None
            v = human if human is not None else default_speed * k
            if human is not None:
                anatomical.add(name)
        velocity_limits[name] = float(v)
    velocity_groups = hinge_groups(model, anatomical)

    # -- rest pose ---------------------------------------------------------------
    qpos = _rest_qpos(mp, model, root, mjcf, where)
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    rest = _frame_positions(model, data, tracked)
    # Put the pelvis above the origin and the lowest point on the floor.
    adr = int(model.jnt_qposadr[root])
    qpos[adr : adr + 2] -= rest["pelvis"][:2]
    contact_sites = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
                     for sites in mp.contacts.values() for s in sites]
    floor = min(
        [lowest_z(model, data, character_geoms(model, collision_only=True))]
        + [float(data.site_xpos[s][2]) for s in contact_sites]
    )
    if not math.isfinite(floor):
        floor = lowest_z(model, data)
    if not math.isfinite(floor):
        raise MappingError("the model has no geoms or contact sites to stand on", path=mjcf)
    qpos[adr + 2] -= floor
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    rest = _frame_positions(model, data, tracked)

    present = set(tracked)
    segments = {}
    for canon in tracked:
        parent = canonical_parent(canon, present)
        if parent is not None:
            segments[(parent, canon)] = float(np.linalg.norm(rest[canon] - rest[parent]))
    hips = [rest[h][2] for h in ("left_hip", "right_hip")]
    height = highest_z(model, data)
    total_mass = float(np.sum(model.body_mass))

    qpos.setflags(write=False)
    return Character(
        name=mp.name or (mjcf.stem if mjcf.stem != "scene" else DEFAULT_CHARACTER),
        mjcf_path=mjcf,
        map_path=mp_file,
        mapping_proposed=mp_file is None and mp.path is not None,
        model=model,
        root_joint=model.joint(root).name,
        tracked=tracked,
        contacts=dict(mp.contacts),
        rest_qpos=qpos,
        joint_limits=joint_limits,
        velocity_limits=velocity_limits,
        velocity_groups=velocity_groups,
        rest_pose=_rest_words(mp, model),
        segment_lengths=segments,
        hip_height=float(np.mean(hips)),
        height=float(height),
        total_mass=total_mass,
        _rest=rest,
    )


def untracked_limbs(tracked) -> tuple[str, ...]:
    """The optional limbs (:data:`OPTIONAL_LIMBS`) a character does not map, in table order:
    ``("left_arm", "right_arm")`` for a legs-only robot.  ``tracked``: canonical joint names
    (a :class:`Character`'s ``tracked``)."""
    return tuple(limb for limb, (core, _) in OPTIONAL_LIMBS.items() if not any(j in tracked for j in core))


def _limbs_phrase(limbs: tuple[str, ...]) -> str:
    """``no arms`` for both arms, ``no left arm`` for one (:func:`untracked_limbs`)."""
    kinds = {x.split("_", 1)[1] for x in limbs}
    if len(limbs) == 2 * len(kinds):
        return "no " + " or ".join(sorted(k + "s" for k in kinds))
    return "no " + " or ".join(x.replace("_", " ") for x in limbs)


def _check_limbs(tracked: dict[str, TrackedFrame], mp: Mapping, where: Path) -> None:
    """An optional limb is mapped whole or not at all: its core joints all or none, the joints
    hanging on it only with it (a wrist with no elbow tracks nothing the targets can reach)."""

    def error(message: str, key: str) -> MappingError:
        return mp.error(message, "joints", key) if mp.path is not None else MappingError(message, path=where)

    for limb, (core, hung) in OPTIONAL_LIMBS.items():
        what = limb.replace("_", " ")
        have = [j for j in core if j in tracked]
        lack = [j for j in core if j not in tracked]
        if have and lack:
            raise error(f"{', '.join(have)} mapped without {', '.join(lack)}: the {what} is tracked from its "
                        f"{' and '.join(j.split('_', 1)[1] for j in core)} (map all of them, or none for a robot "
                        f"without a {what})", have[0])
        stray = [j for j in hung if j in tracked and not have]
        if stray:
            raise error(f"{', '.join(stray)} mapped without the {what} ({', '.join(core)}): map the {what} too, "
                        f"or leave {', '.join(stray)} out", stray[0])


def _add_foot_contacts(mjcf: Path, mp: Mapping, model: mujoco.MjModel, tracked: dict, where: Path):
    """A mapping without ``[contacts]``: heel and toe sites from the feet's geometry
    (:mod:`.footprint`), added to the model; returns the recompiled model and its frames."""
    from .footprint import foot_contact_points

    qpos = _rest_qpos(mp, model, _root_joint(model, mjcf), mjcf, where)
    ankles = {}
    for side in ("left", "right"):
        tf = tracked[f"{side}_ankle"]
        ankles[side] = tf.body_id(model)
    found = foot_contact_points(model, qpos, ankles)
    if set(found) != {"left", "right"}:
        return model, tracked
    for side, points in found.items():
        for name, body, pos in points:
            mp.sites[name] = (model.body(body).name, (float(pos[0]), float(pos[1]), float(pos[2])))
        mp.contacts[side] = tuple(name for name, _, _ in points)
    model = _load_model(mjcf, mp)
    return model, _resolve_frames(mp, model)


def _rest_key(mp: Mapping, model: mujoco.MjModel) -> str | None:
    """The keyframe the rest pose starts from: the mapping's ``[rest] keyframe``, else one named
    ``rest``, else none (the zero pose).  A mapping file proposed by ``character init`` names the
    standing keyframe it found (``home``, ``stand``...)."""
    if mp.rest_keyframe is None and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "rest") >= 0:
        return "rest"
    return mp.rest_keyframe


def _rest_words(mp: Mapping, model: mujoco.MjModel) -> str:
    """Where the rest pose comes from, in words (:attr:`Character.rest_pose`)."""
    key = _rest_key(mp, model)
    out = f"keyframe {key!r}" if key is not None else "zero pose (no keyframe)"
    if mp.rest_joints:
        out += f", {len(mp.rest_joints)} joint(s) set by [rest.joints]"
    return out


def _rest_qpos(mp: Mapping, model: mujoco.MjModel, root: int, mjcf: Path, where: Path) -> np.ndarray:
    qpos = model.qpos0.copy()
    key_name = _rest_key(mp, model)
    if key_name is not None:
        k = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, key_name)
        if k < 0:
            raise mp.error(f"the model has no keyframe {key_name!r}", "rest", "keyframe")
        qpos = model.key_qpos[k].copy()
    for jn, value in mp.rest_joints.items():
        j = _joint_id(mp, model, "rest.joints", jn)
        if int(model.jnt_type[j]) not in _LIMITED:
            raise mp.error("only hinge and slide joints can be set in [rest.joints]", "rest.joints", jn)
        qpos[model.jnt_qposadr[j]] = math.radians(value) if _is_angular(model, j) else value
    # Stand the model up: its up axis to +Z, its forward axis to +X.
    adr = int(model.jnt_qposadr[root])
    R = _up_forward_rotation(mp.up, mp.forward)
    q_fix = Rotation.from_matrix(R).as_quat()
    q_root = wxyz_to_xyzw(qpos[adr + 3 : adr + 7])
    q_root = q_root / np.linalg.norm(q_root)
    qpos[adr + 3 : adr + 7] = xyzw_to_wxyz(quat_mul(q_fix, q_root))
    qpos[adr : adr + 3] = R @ qpos[adr : adr + 3]
    for j in range(model.njnt):
        if int(model.jnt_type[j]) in _LIMITED and model.jnt_limited[j]:
            a = int(model.jnt_qposadr[j])
            lo, hi = model.jnt_range[j]
            if not lo - 1e-9 <= qpos[a] <= hi + 1e-9:
                raise MappingError(
                    f"rest pose puts joint {model.joint(j).name!r} at {qpos[a]:.4g}, "
                    f"outside its range [{lo:.4g}, {hi:.4g}]",
                    path=where,
                )
    return qpos


def _frame_positions(
    model: mujoco.MjModel, data: mujoco.MjData, tracked: dict[str, TrackedFrame]
) -> dict[str, np.ndarray]:
    out = {}
    for canon, tf in tracked.items():
        out[canon] = tf.position(model, data).copy()
    return out
