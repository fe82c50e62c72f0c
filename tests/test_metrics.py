"""Quality metrics for feet (skating, hovering, source penetration) on synthetic and real motion."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from physmocap import metrics
from physmocap.errors import OptionError
from physmocap.ik.contacts import CONTACT_LABELS, Contacts, FloorPlane, detect_contacts
from physmocap.models import load_character
from physmocap.sources import load_motion
from physmocap.sources.profiles import map_skeleton
from physmocap.trajectory import Trajectory

from conftest import SHARED_BVH, shared_file

# ---------------------------------------------------------------------------
# Pure functions
# ---------------------------------------------------------------------------


def _line(speed_xy: tuple[float, float], z: float = 0.0, frames: int = 50, fps: float = 50.0) -> np.ndarray:
    t = np.arange(frames) / fps
    return np.stack([speed_xy[0] * t, speed_xy[1] * t, np.full(frames, z)], axis=1)[:, None, :]


def test_skating_of_still_and_sliding_points():
    fps = 50.0
    still = metrics.skating(_line((0, 0)), fps, np.ones((50, 1), bool))
    assert still["mean_cm_s"] == 0.0 and still["max_cm_s"] == 0.0 and still["share_over_5cm_s"] == 0.0
    slow = metrics.skating(_line((0.03, 0.0)), fps, np.ones((50, 1), bool))
    assert slow["mean_cm_s"] == pytest.approx(3.0) and slow["share_over_5cm_s"] == 0.0
    fast = metrics.skating(_line((0.06, 0.08)), fps, np.ones((50, 1), bool))
    assert fast["p95_cm_s"] == pytest.approx(10.0) and fast["share_over_5cm_s"] == 1.0
    assert fast["stance_samples"] == 50


def test_skating_without_stance_is_null():
    out = metrics.skating(_line((0.1, 0)), 50.0, np.zeros((50, 1), bool))
    assert out["mean_cm_s"] is None and out["share_over_5cm_s"] is None and out["stance_samples"] == 0


@settings(max_examples=25, deadline=None)
@given(vz=st.floats(-2, 2), vx=st.floats(-1, 1), fps=st.sampled_from([30.0, 60.0, 120.0]))
def test_skating_ignores_vertical_motion(vx, vz, fps):
    t = np.arange(20) / fps
    p = np.stack([vx * t, np.zeros_like(t), vz * t], axis=1)[:, None, :]
    v = metrics.horizontal_speeds(p, fps)
    np.testing.assert_allclose(v, abs(vx), atol=1e-9)


def test_stance_rules():
    h = np.array([[-0.02, 0.05], [0.0, 0.06], [0.01, 0.2], [0.0101, 0.059]])
    np.testing.assert_array_equal(metrics.character_stance(h)[:, 0], [True, True, True, False])
    # a source point is in stance within 1 cm of its own 5th percentile
    src = metrics.source_stance(np.column_stack([np.linspace(0.05, 0.30, 101), np.full(101, np.nan)]))
    assert src[:, 0].sum() == 9  # 0.05 + p5 offset (0.0125) + 1 cm covers samples up to 0.0725
    assert not src[:, 1].any()


def test_hovering_is_clipped_at_the_floor():
    h = np.array([[0.003, -0.01], [0.004, 0.5], [0.5, 0.5]])
    lab = np.array([[True, True], [True, False], [False, False]])
    out = metrics.hovering(h, lab)
    assert out["contact_samples"] == 3
    assert out["median_mm"] == pytest.approx(3.0)
    assert metrics.hovering(h, np.zeros_like(lab))["median_mm"] is None


# ---------------------------------------------------------------------------
# A character standing, hovering, sliding
# ---------------------------------------------------------------------------


def _standing(name: str, frames: int = 40, fps: float = 40.0, dz: float = 0.0, vx: float = 0.0):
    character = load_character(name)
    model = character.model
    q0 = model.key_qpos[0].copy() if model.nkey else model.qpos0.copy()
    qpos = np.tile(q0, (frames, 1))
    qpos[:, 2] += dz
    qpos[:, 0] += vx * np.arange(frames) / fps
    return Trajectory(character=character, qpos=qpos, fps=fps)


def _all_contact(frames: int) -> Contacts:
    return Contacts(labels={n: np.ones(frames, bool) for n in CONTACT_LABELS}, fps=40.0)


@pytest.mark.parametrize("name", ["humanoid", "robot"])
def test_standing_character_has_clean_feet(name):
    traj = _standing(name)
    out = metrics.trajectory_metrics(traj, _all_contact(traj.num_frames))
    sites = sum(len(s) for s in traj.character.contacts.values())
    assert out["skating"]["stance_samples"] == sites * traj.num_frames
    assert out["skating"]["max_cm_s"] == pytest.approx(0.0, abs=1e-9)
    assert out["hovering"]["p95_mm"] == pytest.approx(0.0, abs=0.01)
    assert out["penetration"]["max_mm"] < 0.01


@pytest.mark.parametrize("name", ["humanoid", "robot"])
def test_hovering_and_sliding_character(name):
    traj = _standing(name, dz=0.003, vx=0.10)
    out = metrics.trajectory_metrics(traj, _all_contact(traj.num_frames))
    assert out["hovering"]["median_mm"] == pytest.approx(3.0, abs=0.01)
    assert out["skating"]["mean_cm_s"] == pytest.approx(10.0, rel=1e-6)
    assert out["skating"]["share_over_5cm_s"] == 1.0
    high = metrics.character_skating(_standing(name, dz=0.02))
    assert high["stance_samples"] == 0 and high["mean_cm_s"] is None  # 2 cm up: no stance
    sunk = metrics.penetration(traj.model, _standing(name, dz=-0.005).qpos)
    assert sunk["max_mm"] == pytest.approx(5.0, abs=0.05) and sunk["share_over_1mm"] == 1.0


def test_hovering_needs_matching_frames():
    traj = _standing("humanoid")
    with pytest.raises(OptionError, match="cover 7 frames but the trajectory has 40"):
        metrics.character_hovering(traj, _all_contact(7))


def test_trajectory_metrics_keeps_its_keys_without_contacts():
    out = metrics.trajectory_metrics(_standing("robot"))
    assert {"frames", "fps", "non_finite", "joint_limits", "velocity", "penetration", "smoothness", "skating"} <= set(out)
    assert "hovering" not in out


# ---------------------------------------------------------------------------
# Source motions (the shared recordings)
# ---------------------------------------------------------------------------

_SOURCES: dict = {}


def _source(name: str):
    if name not in _SOURCES:
        motion = load_motion(shared_file(name))
        idx = dict(map_skeleton(motion.skeleton).indices)
        _SOURCES[name] = (motion, idx, metrics.source_metrics(motion, idx, detect_contacts(motion, idx)))
    return _SOURCES[name]


# mean skating (cm/s) of the raw recordings under metrics.md's source stance rule
EXPECTED_SKATING = {
    "cmu_12_01_walk.bvh": (12.0, 25.0),
    "pymo_walk.bvh": (30.0, 50.0),
    "cmu_01_01_jumps.bvh": (8.0, 20.0),
    "optitrack_hops_crouch.bvh": (0.2, 2.0),
}


@pytest.mark.parametrize("name", SHARED_BVH)
def test_raw_recordings_skate(name):
    motion, idx, out = _source(name)
    sk = out["skating"]
    lo, hi = EXPECTED_SKATING[name]
    assert lo < sk["mean_cm_s"] < hi
    assert sk["p95_cm_s"] >= sk["mean_cm_s"] and sk["max_cm_s"] >= sk["p95_cm_s"]
    assert 0.0 <= sk["share_over_5cm_s"] <= 1.0
    # every figure is finite or None
    for group in ("skating", "penetration", "hovering"):
        for v in out[group].values():
            assert v is None or np.isfinite(v)


def test_walks_skate_more_than_the_standing_clip():
    walk = _source("cmu_12_01_walk.bvh")[2]["skating"]
    still = _source("optitrack_hops_crouch.bvh")[2]["skating"]
    assert walk["share_over_5cm_s"] > 5 * still["share_over_5cm_s"]


def test_source_penetration_uses_the_floor_plane():
    motion, idx, _ = _source("optitrack_hops_crouch.bvh")
    flat = metrics.source_penetration(motion, 0.0)
    plane = metrics.source_penetration(motion, FloorPlane(height=0.0))
    assert flat == plane
    lowered = metrics.source_penetration(motion, -1.0)
    assert lowered["max_mm"] == 0.0 and lowered["share_over_1mm"] == 0.0
    default = metrics.source_penetration(motion)
    assert 0.0 <= default["share_over_1mm"] < 0.2  # a robust floor: few frames below it


# ---------------------------------------------------------------------------
# Exact lowest points of geoms (penetration)
# ---------------------------------------------------------------------------

_GEOMS_XML = """
<mujoco>
  <asset>
    <mesh name="tet" vertex="0 0 0  0.1 0 0  0 0.2 0  0 0 0.3"/>
  </asset>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="b" pos="0 0 1">
      <freejoint/>
      <geom name="sphere" type="sphere" size="0.05" pos="0.3 0 0"/>
      <geom name="capsule" type="capsule" size="0.04 0.1" pos="0 0.3 0" euler="20 30 40"/>
      <geom name="cylinder" type="cylinder" size="0.06 0.08" pos="-0.3 0 0" euler="50 10 0"/>
      <geom name="box" type="box" size="0.1 0.05 0.02" pos="0 -0.3 0" euler="10 70 5"/>
      <geom name="ellipsoid" type="ellipsoid" size="0.1 0.05 0.03" pos="0 0 0.3" euler="35 0 60"/>
      <geom name="mesh" type="mesh" mesh="tet" pos="0 0 -0.3" euler="15 25 35"/>
    </body>
  </worldbody>
</mujoco>
"""


def _surface_samples(model, data, g, n=64):
    """Brute-force points on a geom's surface in world coordinates."""
    t = int(model.geom_type[g])
    s = model.geom_size[g]
    G = mujoco.mjtGeom
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, n), np.linspace(0, np.pi, n))
    sph = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], -1).reshape(-1, 3)
    if t == int(G.mjGEOM_SPHERE):
        local = s[0] * sph
    elif t == int(G.mjGEOM_CAPSULE):
        local = np.vstack([s[0] * sph + [0, 0, s[1]], s[0] * sph - [0, 0, s[1]]])
    elif t == int(G.mjGEOM_ELLIPSOID):
        local = sph * s
    elif t == int(G.mjGEOM_BOX):
        local = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)]) * s
    elif t == int(G.mjGEOM_CYLINDER):
        a = np.linspace(0, 2 * np.pi, 4 * n)
        ring = np.stack([s[0] * np.cos(a), s[0] * np.sin(a), np.zeros_like(a)], -1)
        local = np.vstack([ring + [0, 0, s[1]], ring - [0, 0, s[1]]])
    else:
        mid = model.geom_dataid[g]
        local = model.mesh_vert[model.mesh_vertadr[mid] : model.mesh_vertadr[mid] + model.mesh_vertnum[mid]]
    R = data.geom_xmat[g].reshape(3, 3)
    return data.geom_xpos[g] + local @ R.T


@settings(max_examples=12, deadline=None)
@given(q=st.tuples(*[st.floats(-1, 1) for _ in range(4)]).filter(lambda q: np.linalg.norm(q) > 0.1))
def test_geom_lowest_heights_are_exact(q):
    model = mujoco.MjModel.from_xml_string(_GEOMS_XML)
    data = mujoco.MjData(model)
    data.qpos[3:7] = np.array(q) / np.linalg.norm(q)
    mujoco.mj_kinematics(model, data)
    geoms = np.arange(1, model.ngeom)
    z = metrics.geom_lowest_heights(model, data, geoms)
    for k, g in enumerate(geoms):
        brute = _surface_samples(model, data, g)[:, 2].min()
        # sampled surfaces lie on or above the true lowest point, within the sampling step
        assert z[k] <= brute + 1e-9, model.geom(g).name
        assert brute - z[k] < 2e-3, model.geom(g).name
    assert np.isinf(metrics.geom_lowest_heights(model, data, np.array([0])))[0]  # the plane


def test_labelled_skating_is_the_labelled_subset():
    traj = _standing("humanoid", vx=0.10)
    every = metrics.trajectory_metrics(traj, _all_contact(traj.num_frames))
    assert every["skating_labelled"] == every["skating"]
    none = Contacts(labels={n: np.zeros(traj.num_frames, bool) for n in CONTACT_LABELS}, fps=traj.fps)
    assert metrics.labelled_skating(traj, none)["stance_samples"] == 0
    heels = Contacts(labels={n: np.full(traj.num_frames, n.endswith("heel")) for n in CONTACT_LABELS}, fps=traj.fps)
    assert metrics.labelled_skating(traj, heels)["stance_samples"] == 2 * traj.num_frames


def test_source_labelled_skating_is_a_subset():
    motion, idx, out = _source("cmu_12_01_walk.bvh")
    assert 0 < out["skating_labelled"]["stance_samples"] <= out["skating"]["stance_samples"]
    # the raw walk slides less while its feet are labelled down than over all its low frames
    assert out["skating_labelled"]["mean_cm_s"] < out["skating"]["mean_cm_s"]
