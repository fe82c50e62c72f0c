"""Map a source skeleton onto the canonical joints.

:func:`map_skeleton` is what the retargeter calls; :func:`detect_profile`
is its automatic part.

Detection by names: every built-in profile is matched against the
skeleton's normalised joint names (:mod:`.names`), then completed by the
rules of :mod:`.rules`.  Profiles are ranked by, in order:

1. how many required canonical joints they map;
2. whether the skeleton carries the profile's tool prefix (``mixamorig``...);
3. the share of the skeleton's joints (end sites aside) whose names the
   profile knows: a more specific convention explains more of them;
4. the share of the profile's names the skeleton has;
5. how many canonical joints they map; then the order of :data:`PROFILES`.

If the best profile misses a required joint, the skeleton's shape is tried
(:mod:`.topology`) and used when it maps more required joints.
"""

from __future__ import annotations

import difflib
import os
from typing import Iterable, Mapping

from ...canonical import CANONICAL_NAMES, REQUIRED_JOINTS
from ...errors import MappingError, OptionError, warn
from ...motion import Motion, Skeleton
from .jointmap import JointMap
from .mapfile import UserMapping, check_mapping, load_mapping_file
from .names import normalize_name, skeleton_keys
from .rules import complete, side_check
from .structure import SkeletonView, is_upright, standing_pose
from .tables import PROFILES, Profile, profile_names
from .topology import topology_map

__all__ = ["detect_profile", "map_skeleton", "match_profile", "rank_profiles"]


class _Source:
    """A skeleton with its view, keys and the lookups every profile needs."""

    def __init__(self, obj: Skeleton | Motion) -> None:
        if isinstance(obj, Motion):
            self.skeleton = obj.skeleton
            self.origin = obj.source
        elif isinstance(obj, Skeleton):
            self.skeleton = obj
            self.origin = None
        else:
            raise TypeError(f"expected a Skeleton or a Motion, got {type(obj).__name__}")
        pose, where = standing_pose(obj)
        self.pose_name = where
        self.view = SkeletonView(self.skeleton, pose)
        self.keys, self.prefix = skeleton_keys(self.skeleton.names)
        self.by_key: dict[str, list[int]] = {}
        for j, k in enumerate(self.keys):
            self.by_key.setdefault(k, []).append(j)
        # prefer real joints over end sites for one key
        for k, js in self.by_key.items():
            js.sort(key=lambda j: (bool(self.skeleton.end_site[j]), j))
        self.body = [j for j in range(self.skeleton.num_joints) if not self.skeleton.end_site[j]]

    def find(self, name: str) -> int | None:
        js = self.by_key.get(normalize_name(name))
        return js[0] if js else None


def match_profile(
    src: _Source,
    profile: Profile,
    preset: Mapping[str, int] | None = None,
    skip: Iterable[str] = (),
) -> dict[str, int]:
    """Canonical joint -> joint index from ``profile``'s names (no rules applied).

    Canonical joints are filled in canonical order; a source joint is given to
    the first canonical joint that names it.  ``preset`` joints (the user's)
    are kept and their source joints are not given to others; ``skip``
    canonical joints are left out.
    """
    out: dict[str, int] = dict(preset or {})
    taken: set[int] = set(out.values())
    skipped = set(skip)
    for c in CANONICAL_NAMES:
        if c in out or c in skipped:
            continue
        for cand in profile.joints.get(c, ()):
            js = src.by_key.get(normalize_name(cand), [])
            j = next((j for j in js if j not in taken), None)
            if j is not None:
                out[c] = j
                taken.add(j)
                break
    return out


def _score(src: _Source, profile: Profile, idx: dict, derived: dict) -> tuple:
    req = sum(1 for c in REQUIRED_JOINTS if c in idx or c in derived)
    prefix = bool(src.prefix) and src.prefix in profile.prefixes
    body_keys = [src.keys[j] for j in src.body]
    known = sum(1 for k in body_keys if k in profile.keys)
    skel_share = known / max(len(body_keys), 1)
    prof_share = len(profile.keys & set(body_keys)) / max(len(profile.keys), 1)
    return (req, prefix, round(skel_share, 9), round(prof_share, 9), len(idx) + len(derived))


def rank_profiles(obj: Skeleton | Motion) -> list[tuple[str, tuple]]:
    """Every built-in profile with its detection score, best first (for diagnostics)."""
    src = obj if isinstance(obj, _Source) else _Source(obj)
    scored = []
    for order, p in enumerate(PROFILES.values()):
        idx, derived, _ = complete(src.view, match_profile(src, p))
        scored.append((_score(src, p, idx, derived), -order, p.name))
    scored.sort(reverse=True)
    return [(name, score) for score, _, name in scored]


def _base(src: _Source, profile: str | None) -> tuple[str, dict[str, int], list[str]]:
    """``(label, explicit indices, notes)`` before the rules, for ``profile``."""
    if profile in (None, "auto"):
        ranking = rank_profiles(src)
        best_name, best_score = ranking[0]
        explicit = match_profile(src, PROFILES[best_name])
        n_req = len(REQUIRED_JOINTS)
        if best_score[0] == n_req and best_score[2] > 0:
            return best_name, explicit, []
        topo, tnotes = topology_map(src.view)
        t_idx, t_der, _ = complete(src.view, topo)
        t_req = sum(1 for c in REQUIRED_JOINTS if c in t_idx or c in t_der)
        if t_req > best_score[0] or (best_score[2] == 0 and t_req == best_score[0]):
            return "topology", topo, [
                f"no profile knows these joint names (best: {best_name}, "
                f"{best_score[0]}/{n_req} required joints); mapped by the skeleton's shape"
            ] + tnotes
        return best_name, explicit, tnotes if best_score[0] < n_req else []
    if profile == "topology":
        topo, tnotes = topology_map(src.view)
        return "topology", topo, tnotes
    if profile == "none":
        return "none", {}, []
    if profile not in PROFILES:
        close = difflib.get_close_matches(str(profile), profile_names(), n=3)
        hint = f" (did you mean {' or '.join(close)}?)" if close else ""
        raise OptionError(
            f"unknown skeleton profile {profile!r}{hint}; known profiles: "
            + ", ".join(profile_names())
            + " (or 'auto')"
        )
    return profile, match_profile(src, PROFILES[profile]), []


def _resolve_user(src: _Source, user: UserMapping) -> tuple[dict[str, int], set[str]]:
    """User entries -> (canonical -> index, canonical joints switched off)."""
    names = src.skeleton.names
    exact = {n: j for j, n in enumerate(names)}
    out: dict[str, int] = {}
    off: set[str] = set()
    owner: dict[int, str] = {}
    for c, cands in user["joints"].items():
        line = user["lines"].get(c)
        if cands is None:
            off.add(c)
            continue
        j = None
        for cand in cands:
            if cand in exact:
                j = exact[cand]
                break
            js = src.by_key.get(normalize_name(cand), [])
            if len(js) > 1 and not all(src.skeleton.end_site[k] for k in js[1:]):
                raise MappingError(
                    f"entry {c} = {cand!r} matches several joints "
                    f"({', '.join(names[k] for k in js)}); give the exact name",
                    path=user["path"],
                    line=line,
                )
            if js:
                j = js[0]
                break
        if j is None:
            wanted = " or ".join(repr(x) for x in cands)
            close = difflib.get_close_matches(cands[0], [names[k] for k in src.body], n=3)
            hint = f" (did you mean {' or '.join(repr(x) for x in close)}?)" if close else ""
            raise MappingError(
                f"entry {c} = {wanted}: the skeleton has no such joint{hint}. "
                f"Its joints: {_offered(src)}",
                path=user["path"],
                line=line,
            )
        if j in owner:
            raise MappingError(
                f"entry {c} = {names[j]!r}: that joint is already mapped to {owner[j]}; "
                "a source joint can be one canonical joint only",
                path=user["path"],
                line=line,
            )
        owner[j] = c
        out[c] = j
    return out, off


def _offered(src: _Source) -> str:
    names = src.skeleton.names
    body = ", ".join(names[j] for j in src.body)
    n_end = src.skeleton.num_joints - len(src.body)
    return body + (f" (and {n_end} end sites)" if n_end else "")


def detect_profile(skeleton: Skeleton | Motion) -> JointMap:
    """The best mapping found automatically: by names, else by shape.

    Never raises for missing joints: check :meth:`JointMap.missing`.  Pass a
    :class:`~physmocap.motion.Motion` rather than its skeleton when its rest
    pose may not be a standing body (LAFAN1, Bandai Namco): the shape is then
    read from an animated frame.
    """
    return map_skeleton(skeleton, required=())


def map_skeleton(
    skeleton: Skeleton | Motion,
    profile: str | None = None,
    mapping: str | os.PathLike | Mapping | None = None,
    required: Iterable[str] = REQUIRED_JOINTS,
    *,
    source: str | os.PathLike | None = None,
) -> JointMap:
    """Map a source skeleton onto the canonical joints.

    Args:
        skeleton: The source :class:`~physmocap.motion.Skeleton`, or its
            :class:`~physmocap.motion.Motion` (better: geometry can then come
            from an animated frame when the rest pose is not a standing body).
        profile: A built-in profile name (:data:`PROFILES`), ``"topology"``
            (by shape only), ``"none"`` (only the mapping file), or None /
            ``"auto"`` to detect.  Overrides the mapping file's ``profile``.
        mapping: A mapping file path or an equivalent dict
            (:mod:`.mapfile`); its entries override the profile's choices.
        required: Canonical joints that must be mapped.
        source: The source file, for error messages (default: the motion's).

    Returns:
        The :class:`~.jointmap.JointMap`.

    Raises:
        MappingError: A required joint cannot be mapped (the message lists the
            missing canonical joints and the skeleton's joint names), or a
            mapping entry names a joint the skeleton does not have.
        InputError: The mapping file cannot be read or is not TOML.
        OptionError: ``profile`` is unknown.
    """
    src = _Source(skeleton)
    where = os.fspath(source) if source is not None else src.origin
    user: UserMapping | None = None
    if mapping is not None:
        if isinstance(mapping, Mapping):
            user = check_mapping(mapping, None)
        else:
            user = load_mapping_file(mapping)
    chosen = profile if profile is not None else (user["profile"] if user else None)
    label, explicit, notes = _base(src, chosen)
    fixed: set[str] = set()
    based_on = None
    if user and user["joints"]:
        given, off = _resolve_user(src, user)
        fixed = set(given) | off
        if label in PROFILES:
            # the profile fills the rest around the user's joints
            explicit = match_profile(src, PROFILES[label], preset=given, skip=off)
        else:
            used = set(given.values())
            explicit = {c: j for c, j in explicit.items() if c not in fixed and j not in used}
            explicit.update(given)
        based_on = label
        label = "custom"
        notes = notes + [f"mapping {user['path'] or '(dict)'} applied over profile {based_on}"]
    idx, derived, rule_notes = complete(src.view, explicit, fixed)
    jmap = JointMap(
        profile=label,
        indices=idx,
        names=src.skeleton.names,
        derived=derived,
        notes=tuple(notes + rule_notes),
        based_on=based_on,
        pose=src.pose_name,
    )
    missing = jmap.missing(required)
    if missing:
        what = {"topology": "the skeleton's shape", "none": "no profile"}
        mapped_by = what.get(based_on or label, f"profile {based_on or label}")
        if based_on:
            mapped_by += f" with the mapping {user['path'] or '(dict)'}" if user else ""
        raise MappingError(
            f"cannot map the required canonical joint(s) {', '.join(missing)} "
            f"(tried {mapped_by}). The skeleton's joints are: {_offered(src)}. "
            "Name the source joint for each in a mapping file, e.g. "
            f'[joints] {missing[0]} = "<joint name>", and pass it with --source-map (retarget, replay) or --map (inspect) '
            "(physmocap inspect FILE --emit-map writes a starting file)",
            path=where,
        )
    msg = side_check(src.view, idx) if is_upright(src.view.pose) else None
    if msg:
        warn(f"{where}: {msg}" if where else msg)
    return jmap
