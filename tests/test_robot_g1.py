"""A real robot model (issue 13, first part): the Unitree G1 with its meshes, no user mapping."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from conftest import REPO, SHARED_DATA, shared_file
from physmocap.errors import MappingError

G1 = SHARED_DATA.parent / "robots" / "unitree_g1" / "g1_mocap_29dof.xml"


@pytest.fixture(scope="module")
def g1_walk():
    if not G1.exists():
        pytest.skip(f"the Unitree G1 model is not here: {G1} (../shared absent)")
    from physmocap import load_motion, retarget
    from physmocap.models import load_character

    ch = load_character(G1)  # the bundled mapping file is found by the model's file name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traj = retarget(load_motion(shared_file("pymo_walk.bvh")), ch, progress=False, end=240)
    return ch, traj


def test_g1_retargets_without_a_user_mapping(g1_walk):
    from physmocap import metrics
    from physmocap.metrics.fidelity import trajectory_fidelity

    ch, traj = g1_walk
    assert ch.name == "unitree_g1" and set(ch.contacts) == {"left", "right"}
    assert np.all(np.isfinite(traj.qpos))
    assert metrics.joint_limit_violations(ch.model, traj.qpos)["count"] == 0
    assert metrics.penetration(ch.model, traj.qpos)["max_mm"] < 1.0
    fid = trajectory_fidelity(traj)
    assert max(v.median_deg for v in fid.segments.values()) < 8.0
    assert fid.facing_p95_deg < 10.0 and fid.path_mean_cm < 3.0


def test_floor_constraint_skips_visual_meshes_and_far_geoms(g1_walk):
    import mujoco

    from physmocap.ik.limits import FloorLimit
    from physmocap.models.geometry import is_visual_only

    ch, traj = g1_walk
    m = ch.model
    limit = FloorLimit(m)
    assert not any(is_visual_only(m, int(g)) for g in limit.geoms)
    assert any(is_visual_only(m, g) for g in range(m.ngeom))
    data = mujoco.MjData(m)
    data.qpos[:] = traj.qpos[0]
    mujoco.mj_kinematics(m, data)
    z, _, _ = limit.heights(data)
    assert np.isinf(z).sum() > 0.5 * len(z)  # the arms' and torso's hull points are not evaluated
    assert np.nanmin(z[np.isfinite(z)]) > -1e-3


def test_added_site_on_a_missing_body_names_the_line(tmp_path):
    if not G1.exists():
        pytest.skip("../shared absent")
    from physmocap.models import load_character

    text = (REPO / "assets" / "mjcf" / "robots" / "g1_mocap_29dof.map.toml").read_text()
    bad = tmp_path / "g1.map.toml"
    bad.write_text(text.replace('neck = { body = "torso_link"', 'neck = { body = "no_such_link"'))
    with pytest.raises(MappingError, match=r"\[sites\] neck: the model has no body 'no_such_link'") as err:
        load_character(G1, bad)
    assert "line" in str(err.value) or err.value.line is not None
