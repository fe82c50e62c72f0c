"""A copy of the default humanoid scaled to an actor's proportions, built with MjSpec.

Every body of the default humanoid carries the site of the canonical joint
that moves it.  For a segment ``(p, c)`` (canonical parent ``p``, child ``c``)
the ratio ``r_pc = L_actor / L_humanoid`` scales:

* the position of the child body (its offset from the parent body), and of an
  end site (``head_end``, ``*_hand_end``, ``*_toe_end``) from its body;
* uniformly, everything else inside the parent body (geom positions, sizes,
  ``fromto`` ends, other sites, the centre of mass) by the mean ratio
  ``g_B`` of the segments leaving that body.

Masses scale with volume, ``m' = m g_B^3``, inertias with ``m L^2``,
``I' = I g_B^5``; with an explicit ``mass`` every body is then rescaled so the
total is that mass.  Segments not given take the mirror side's ratio, else the
stature ratio ``height / 1.75`` when a height is given, else the median of the
given ratios.  The rest pose is re-placed so the lowest geom touches z = 0.
Joint ranges and axes are unchanged (angles do not scale).
"""

from __future__ import annotations

import math
import os
import statistics
from pathlib import Path
from typing import Mapping

import mujoco
import numpy as np

from ..canonical import CANONICAL_NAMES, canonical_parent, mirror_name
from ..errors import OptionError
from ..fileio import OutputSet, atomic_open, check_writable
from ..resources import mjcf_dir
from .anthropometry import DEFAULT_HEIGHT
from .geometry import lowest_z

__all__ = [
    "segment_ratios",
    "scaled_humanoid_spec",
    "write_scaled_humanoid",
    "segment_lengths_from_positions",
]

Segment = tuple[str, str]


def segment_lengths_from_positions(positions: Mapping[str, np.ndarray]) -> dict[Segment, float]:
    """Segment lengths (m) between canonical joints given their rest positions.

    Each present joint is paired with its nearest present canonical ancestor,
    as in :attr:`physmocap.models.Character.segment_lengths`.
    """
    present = {k for k in positions if k in CANONICAL_NAMES}
    out: dict[Segment, float] = {}
    for c in present:
        p = canonical_parent(c, present)
        if p is not None:
            out[(p, c)] = float(np.linalg.norm(np.asarray(positions[c]) - np.asarray(positions[p])))
    return out


def segment_ratios(
    base: Mapping[Segment, float],
    target: Mapping[Segment, float] | None = None,
    height: float | None = None,
) -> dict[Segment, float]:
    """Ratio actor / humanoid for every segment of ``base`` (see module docstring)."""
    target = dict(target or {})
    for seg, length in target.items():
        if seg not in base:
            raise OptionError(
                f"segment {seg[0]} -> {seg[1]} is not a segment of the default humanoid; "
                f"segments are {', '.join(f'{a}->{b}' for a, b in base)}"
            )
        if not (math.isfinite(length) and length > 0):
            raise OptionError(f"segment {seg[0]} -> {seg[1]}: length must be positive, got {length!r}")
    if height is not None and not (math.isfinite(height) and height > 0):
        raise OptionError(f"height must be a positive number of metres, got {height!r}")
    given = {seg: target[seg] / base[seg] for seg in target if base[seg] > 0}
    if height is not None:
        fallback = height / DEFAULT_HEIGHT
    elif given:
        fallback = float(statistics.median(given.values()))
    else:
        fallback = 1.0
    ratios = {}
    for seg in base:
        if seg in given:
            ratios[seg] = given[seg]
            continue
        mirrored = (mirror_name(seg[0]), mirror_name(seg[1]))
        ratios[seg] = given.get(mirrored, fallback)
    return ratios


def scaled_humanoid_spec(
    segment_lengths: Mapping[Segment, float] | None = None,
    height: float | None = None,
    mass: float | None = None,
) -> mujoco.MjSpec:
    """MjSpec of the default humanoid with the actor's segment lengths, stature and mass.

    Args:
        segment_lengths: ``(parent canonical, child canonical) -> metres``, keys as
            in :attr:`Character.segment_lengths` of the default humanoid.
        height: actor's stature (m), for segments not given.
        mass: actor's body mass (kg); default: the humanoid's mass scaled with volume.
    """
    from .character import load_character

    base_char = load_character()
    ratios = segment_ratios(base_char.segment_lengths, segment_lengths, height)
    if mass is not None and not (math.isfinite(mass) and mass > 0):
        raise OptionError(f"mass must be a positive number of kg, got {mass!r}")

    spec = mujoco.MjSpec.from_file(os.fspath(mjcf_dir() / "humanoid.xml"))
    canon_of_body: dict[str, str] = {}
    for body in spec.bodies:
        for site in body.sites:
            if site.name in CANONICAL_NAMES and np.allclose(site.pos, 0.0):
                canon_of_body[body.name] = site.name

    for body in spec.bodies:
        if body.name not in canon_of_body:
            continue
        c = canon_of_body[body.name]
        leaving = [r for (p, _), r in ratios.items() if p == c]
        g = float(np.mean(leaving)) if leaving else ratios[(canonical_parent(c), c)]
        for child in body.bodies:
            cc = canon_of_body.get(child.name)
            r = ratios.get((c, cc), g) if cc else g
            child.pos = np.asarray(child.pos) * r
        for site in body.sites:
            r = ratios.get((c, site.name), g)
            site.pos = np.asarray(site.pos) * r
        for geom in body.geoms:
            geom.pos = np.asarray(geom.pos) * g
            geom.size = np.asarray(geom.size) * g
            ft = np.asarray(geom.fromto)
            if np.all(np.isfinite(ft)):
                geom.fromto = ft * g
        body.ipos = np.asarray(body.ipos) * g
        body.mass = float(body.mass) * g**3
        body.inertia = np.asarray(body.inertia) * g**5

    if mass is not None:
        total = sum(float(b.mass) for b in spec.bodies if b.name != "world")
        k = mass / total
        for body in spec.bodies:
            if body.name != "world":
                body.mass = float(body.mass) * k
                body.inertia = np.asarray(body.inertia) * k

    # Stand on the floor: lower (or raise) the pelvis so the lowest geom touches z = 0.
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    drop = lowest_z(model, data)
    pelvis = spec.body("pelvis")
    pelvis.pos = np.asarray(pelvis.pos) - np.array([0.0, 0.0, drop])
    for key in spec.keys:
        if key.name == "rest":
            q = list(key.qpos)
            q[2] = float(pelvis.pos[2])
            key.qpos = q
    spec.modelname = "humanoid_scaled"
    spec.comment = (
        " Scaled copy of the default physmocap humanoid (physmocap.models.scaling, MjSpec). "
        "World Z-up, floor at z=0, facing +X, left is +Y; keyframe \"rest\" stands on the floor. "
    )
    return spec


def write_scaled_humanoid(
    path: str | os.PathLike,
    segment_lengths: Mapping[Segment, float] | None = None,
    height: float | None = None,
    mass: float | None = None,
):
    """Write the scaled humanoid MJCF to ``path`` and its mapping beside it; return the Character.

    The mapping file ``<stem>.map.toml`` is the default humanoid's (sites keep
    their canonical names).
    """
    from .character import load_character
    from .humanoid_builder import mapping_toml

    out = check_writable(path)
    spec = scaled_humanoid_spec(segment_lengths, height, mass)
    xml = spec.to_xml()
    map_out = out.with_name(out.stem + ".map.toml")
    with OutputSet():  # the MJCF and its mapping renamed into place together, or neither
        with atomic_open(out) as fh:
            fh.write(xml)
        with atomic_open(map_out) as fh:
            fh.write(
                mapping_toml()
                .replace('name = "humanoid"', f'name = "{out.stem}"')
                .replace("(GENERATED by scripts/generate_humanoid.py)", "(scaled copy, physmocap character scale)")
            )
    return load_character(Path(out))
