"""The range-of-motion table is the single source of the default humanoid's joint ranges."""

from __future__ import annotations

import math
import statistics

import mujoco
import numpy as np
import pytest

from conftest import load_script
from physmocap.models import rom
from physmocap.models.humanoid_builder import humanoid_xml, mapping_toml, scene_xml
from physmocap.resources import mjcf_dir

HUMANOID = mjcf_dir() / "humanoid.xml"


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_path(str(HUMANOID))


def test_committed_files_match_the_generator():
    """Regenerating the humanoid from the tables gives the committed files byte for byte."""
    assert HUMANOID.read_text(encoding="utf-8") == humanoid_xml()
    assert (mjcf_dir() / "scene.xml").read_text(encoding="utf-8") == scene_xml("humanoid.xml", "humanoid scene")
    assert (mjcf_dir() / "humanoid.map.toml").read_text(encoding="utf-8") == mapping_toml()


def test_every_hinge_has_the_table_range(model):
    hinges = [model.joint(j).name for j in range(model.njnt)
              if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE)]
    assert sorted(hinges) == sorted(rom.dof_names())
    for name in hinges:
        j = model.joint(name).id
        lo, hi = rom.joint_range_deg(name)
        assert model.jnt_limited[j]
        assert model.jnt_range[j] == pytest.approx([math.radians(lo), math.radians(hi)], abs=1e-12), name
        assert model.jnt_axis[j] == pytest.approx(rom.joint_axis(name)), name


def test_left_right_mirrored():
    for d in rom.ROM_TABLE:
        if not d.sided:
            continue
        left, right = f"left_{d.stem}", f"right_{d.stem}"
        assert rom.joint_range_deg(left) == rom.joint_range_deg(right)
        a, b = rom.joint_axis(left), rom.joint_axis(right)
        assert b == pytest.approx([-a[0], a[1], -a[2]])


def test_policies():
    for d in rom.ROM_TABLE:
        lo_d, hi_d = d.range_deg("default")
        lo_s, hi_s = d.range_deg("strict")
        assert lo_d <= lo_s <= 0.0 <= hi_s <= hi_d, d.stem
        pos = d.positive
        assert hi_d == pytest.approx((max(pos.values.values()) + (rom.MARGIN_DEG if pos.margin else 0)) * d.share, abs=0.06)
        assert hi_s == pytest.approx(statistics.median(pos.values.values()) * d.share, abs=0.06)
    # anatomical stops get no margin
    assert rom.joint_range_deg("left_knee_flexion")[0] == -10.0
    assert rom.joint_range_deg("left_elbow_flexion")[0] == -10.0
    assert rom.joint_range_deg("left_knee_flexion", "strict")[0] == 0.0
    with pytest.raises(ValueError):
        rom.joint_range_deg("left_knee_flexion", "loose")
    with pytest.raises(KeyError):
        rom.dof_entry("left_lumbar_flexion")


def test_spine_split_sums_to_the_region():
    for region, parts in (("flexion", ("lumbar", "thoracic")), ("rotation", ("lumbar", "thoracic"))):
        total = sum(rom.joint_range_deg(f"{p}_{region}")[1] for p in parts)
        entry = rom.dof_entry(f"lumbar_{region}")
        assert total == pytest.approx(entry.positive.amount("default"), abs=0.1)


# site, joint, expected direction of the site's motion for a small positive angle
SIGNS = [
    ("left_knee", "left_hip_flexion", (1, 0, 0)),        # thigh swings forward
    ("right_knee", "right_hip_flexion", (1, 0, 0)),
    ("left_knee", "left_hip_adduction", (0, -1, 0)),     # towards the midline
    ("right_knee", "right_hip_adduction", (0, 1, 0)),
    ("left_ankle", "left_knee_flexion", (-1, 0, 0)),     # shank swings back
    ("left_toe_end", "left_ankle_dorsiflexion", (0, 0, 1)),  # toes up
    ("left_toe_end", "left_toe_extension", (0, 0, 1)),
    ("left_wrist", "left_elbow_flexion", (1, 0, 0)),     # forearm forward
    ("left_elbow", "left_shoulder_flexion", (1, 0, 0)),
    ("left_elbow", "left_shoulder_abduction", (0, 1, 0)),  # arm out to the side
    ("right_elbow", "right_shoulder_abduction", (0, -1, 0)),
    ("left_hand_end", "left_wrist_flexion", (0, -1, 0)),   # towards the palm (facing the thigh)
    ("left_hand_end", "left_wrist_deviation", (1, 0, 0)),  # towards the thumb (forward)
    ("neck", "lumbar_flexion", (1, 0, 0)),                # bend forward
    ("neck", "lumbar_lateral_flexion", (0, -1, 0)),       # bend to the right
    ("head_end", "neck_flexion", (1, 0, 0)),
    ("left_shoulder", "left_clavicle_elevation", (0, 0, 1)),
    ("left_shoulder", "left_clavicle_protraction", (1, 0, 0)),
    ("right_shoulder", "right_clavicle_protraction", (1, 0, 0)),
]


@pytest.mark.parametrize("site,joint,direction", SIGNS)
def test_sign_conventions(model, site, joint, direction):
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    before = data.site(site).xpos.copy()
    data.qpos[model.jnt_qposadr[model.joint(joint).id]] = 0.05
    mujoco.mj_forward(model, data)
    d = data.site(site).xpos - before
    assert d / np.linalg.norm(d) == pytest.approx(direction, abs=0.25)


def test_rotation_signs(model):
    """Internal rotation and pronation turn the front of the left limb towards the midline (-Y)."""
    for joint, body in (("left_hip_rotation", "left_thigh"), ("left_shoulder_rotation", "left_upper_arm"),
                        ("left_forearm_pronation", "left_forearm"), ("lumbar_rotation", "lumbar")):
        data = mujoco.MjData(model)
        data.qpos[model.jnt_qposadr[model.joint(joint).id]] = 0.1
        mujoco.mj_forward(model, data)
        x_axis = data.body(body).xmat.reshape(3, 3)[:, 0]
        expected = 1.0 if joint == "lumbar_rotation" else -1.0  # spine: positive turns to the left
        assert np.sign(x_axis[1]) == expected, joint


def test_generator_script_check_mode():
    mod = load_script("generate_humanoid")
    for path, text in mod.outputs().items():
        assert path.read_text(encoding="utf-8") == text
