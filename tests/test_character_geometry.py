"""Lowest and highest points of every geom type, against sampled surface points."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from physmocap.models.geometry import character_geoms, geom_z_extent, highest_z, lowest_z

XML = """
<mujoco>
  <asset>
    <mesh name="wedge" vertex="0 0 0  0.2 0 0  0 0.1 0  0 0 0.3  0.2 0.1 0.05"/>
  </asset>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <body name="b" pos="0 0 1">
      <freejoint/>
      <geom name="sphere" type="sphere" size="0.1" pos="0.3 0 0"/>
      <geom name="capsule" type="capsule" size="0.05 0.2" pos="0 0.3 0"/>
      <geom name="cylinder" type="cylinder" size="0.05 0.2" pos="0 -0.3 0"/>
      <geom name="box" type="box" size="0.1 0.2 0.3" pos="-0.3 0 0"/>
      <geom name="ellipsoid" type="ellipsoid" size="0.1 0.2 0.05" pos="0 0 0.4"/>
      <geom name="mesh" type="mesh" mesh="wedge" pos="0 0 -0.4"/>
    </body>
  </worldbody>
</mujoco>
"""


def _surface_z(model, data, g, n=4000, rng=np.random.default_rng(0)):
    """z of points on the geom's surface (dense sampling of unit directions)."""
    size = model.geom_size[g]
    R = data.geom_xmat[g].reshape(3, 3)
    p = data.geom_xpos[g]
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    t = model.geom_type[g]
    G = mujoco.mjtGeom
    if t == G.mjGEOM_SPHERE:
        local = size[0] * u
    elif t == G.mjGEOM_CAPSULE:
        local = size[0] * u + np.outer(np.sign(u[:, 2]), [0, 0, size[1]])
    elif t == G.mjGEOM_ELLIPSOID:
        local = size * u
    elif t == G.mjGEOM_BOX:
        local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * size
    elif t == G.mjGEOM_CYLINDER:
        ang = rng.uniform(0, 2 * np.pi, n)
        local = np.stack([size[0] * np.cos(ang), size[0] * np.sin(ang), size[1] * np.sign(u[:, 2])], axis=1)
    else:
        m = model.geom_dataid[g]
        local = model.mesh_vert[model.mesh_vertadr[m] : model.mesh_vertadr[m] + model.mesh_vertnum[m]]
    return p[2] + local @ R[2]


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1))
def test_extent_matches_surface(q):
    model = mujoco.MjModel.from_xml_string(XML)
    data = mujoco.MjData(model)
    data.qpos[3:7] = np.asarray(q) / np.linalg.norm(q)
    mujoco.mj_kinematics(model, data)
    for g in character_geoms(model):
        lo, hi = geom_z_extent(model, data, g)
        z = _surface_z(model, data, g)
        # sampled points never exceed the extent, and come close to it
        assert z.min() >= lo - 1e-9 and z.max() <= hi + 1e-9, model.geom(g).name
        assert z.min() == pytest.approx(lo, abs=5e-3) and z.max() == pytest.approx(hi, abs=5e-3)


def test_world_geoms_are_scenery():
    model = mujoco.MjModel.from_xml_string(XML)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    assert model.geom("floor").id not in character_geoms(model)
    # the mesh's lowest vertex is the lowest point: body z 1 + geom z -0.4 + vertex z 0
    assert lowest_z(model, data) == pytest.approx(0.6, abs=1e-6)  # float32 vertices
    assert geom_z_extent(model, data, model.geom("mesh").id) == pytest.approx((0.6, 0.9), abs=1e-6)
    assert highest_z(model, data) > lowest_z(model, data)
    assert geom_z_extent(model, data, model.geom("floor").id) == (float("inf"), float("-inf"))
