"""Characters: loading, rest pose on the floor, mapping, description."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from physmocap.canonical import REQUIRED_JOINTS
from physmocap.models import load_character
from physmocap.models.geometry import character_geoms, geom_z_extent


def _rest_data(ch):
    data = mujoco.MjData(ch.model)
    data.qpos[:] = ch.rest_qpos
    mujoco.mj_forward(ch.model, data)
    return data


def test_default_humanoid_loads_and_stands_on_floor():
    ch = load_character()
    assert ch.name == "humanoid"
    assert ch.root_joint == "root"
    data = _rest_data(ch)
    lows = [geom_z_extent(ch.model, data, g)[0] for g in character_geoms(ch.model)]
    assert min(lows) == pytest.approx(0.0, abs=1e-6)
    assert min(lows) > -1e-6
    for side, sites in ch.contacts.items():
        for s in sites:
            assert data.site(s).xpos[2] == pytest.approx(0.0, abs=1e-6)
    assert ch.height == pytest.approx(1.75, abs=1e-3)
    assert ch.total_mass == pytest.approx(70.0)
    for j in REQUIRED_JOINTS:
        assert j in ch.tracked


def test_default_humanoid_rest_is_zero_hinges():
    ch = load_character()
    assert np.all(ch.rest_qpos[7:] == 0.0)
    assert np.allclose(ch.rest_qpos[3:7], [1, 0, 0, 0])
    for name, (lo, hi) in ch.joint_limits.items():
        assert lo < 0.0 < hi or lo == 0.0 or hi == 0.0, name
        assert math.isfinite(lo) and math.isfinite(hi)
        assert ch.velocity_limits[name] > 0
