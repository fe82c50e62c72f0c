"""A scaled copy of the default humanoid built with MjSpec."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from physmocap.errors import OptionError
from physmocap.models import load_character
from physmocap.models.geometry import lowest_z
from physmocap.models.scaling import (
    scaled_humanoid_spec,
    segment_lengths_from_positions,
    write_scaled_humanoid,
)


@pytest.fixture(scope="module")
def base():
    return load_character()


def test_segment_lengths_from_positions(base):
    assert segment_lengths_from_positions(base.rest_positions()) == pytest.approx(base.segment_lengths)


def test_height_only_scales_everything(base, tmp_path):
    ch = write_scaled_humanoid(tmp_path / "small.xml", height=1.50)
    k = 1.50 / 1.75
    assert ch.height == pytest.approx(1.50, abs=1e-4)
    assert ch.hip_height == pytest.approx(base.hip_height * k, abs=1e-4)
    for seg, length in base.segment_lengths.items():
        assert ch.segment_lengths[seg] == pytest.approx(length * k, rel=1e-4), seg
    assert ch.total_mass == pytest.approx(70.0 * k**3, rel=1e-3)
    assert ch.joint_limits == base.joint_limits  # angles do not scale


def test_measured_segments_and_mass(base, tmp_path):
    target = {("left_hip", "left_knee"): 0.47, ("right_knee", "right_ankle"): 0.39,
              ("left_shoulder", "left_elbow"): 0.30}
    ch = write_scaled_humanoid(tmp_path / "actor.xml", target, height=1.8, mass=82.0)
    for (p, c), length in target.items():
        assert ch.segment_lengths[(p, c)] == pytest.approx(length, abs=1e-6)
    # the other side mirrors the given one
    assert ch.segment_lengths[("right_hip", "right_knee")] == pytest.approx(0.47, abs=1e-6)
    assert ch.segment_lengths[("left_knee", "left_ankle")] == pytest.approx(0.39, abs=1e-6)
    assert ch.total_mass == pytest.approx(82.0, rel=1e-5)
    # it stands on the floor with the contact sites at z = 0
    data = mujoco.MjData(ch.model)
    data.qpos[:] = ch.rest_qpos
    mujoco.mj_forward(ch.model, data)
    assert lowest_z(ch.model, data) == pytest.approx(0.0, abs=1e-6)
    for sites in ch.contacts.values():
        for s in sites:
            assert data.site(s).xpos[2] == pytest.approx(0.0, abs=1e-6)
    # the keyframe "rest" in the written file is that standing pose
    key = ch.model.key("rest").qpos
    assert np.allclose(key, ch.rest_qpos, atol=1e-9)


def test_bad_segments():
    with pytest.raises(OptionError, match="not a segment"):
        scaled_humanoid_spec({("left_hip", "left_ankle"): 0.8})
    with pytest.raises(OptionError, match="positive"):
        scaled_humanoid_spec({("left_hip", "left_knee"): -1.0})
    with pytest.raises(OptionError, match="mass"):
        scaled_humanoid_spec(height=1.7, mass=0.0)
