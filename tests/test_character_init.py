"""``physmocap character init`` (issue 13): a mapping proposed from an MJCF's names and tree.

Synthetic robots named in the usual ways (``left_knee_link``, ``l_calf_link``, ``L_KNEE``,
``LeftLeg``, anonymous ``b7``), one without toes, wrists or neck, one with mesh feet; the
proposal must load as a character unedited.  On the Unitree G1 (../shared) it must pick the
bundled, hand-written mapping's bodies for the major joints and retarget the walk alike.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from conftest import REPO, SHARED_DATA, shared_file
from physmocap.cli import main
from physmocap.errors import InputError, MappingError
from physmocap.models import load_character
from physmocap.models.propose import name_side, propose_mapping

G1 = SHARED_DATA.parent / "robots" / "unitree_g1" / "g1_mocap_29dof.xml"
G1_BUNDLED = REPO / "assets" / "mjcf" / "robots" / "g1_mocap_29dof.map.toml"

# -- a synthetic humanoid robot, named by a style --------------------------------------------

_MESH_FOOT = (
    '<mesh name="foot_mesh" vertex="-0.06 -0.04 -0.06  0.14 -0.04 -0.06  -0.06 0.04 -0.06  0.14 0.04 -0.06 '
    '-0.06 -0.04 -0.01  0.14 -0.04 -0.01  -0.06 0.04 -0.01  0.14 0.04 -0.01"/>'
)


def _robot(names: dict, *, arms=True, toes=True, wrists=True, neck=True, clavicle=False, mesh_feet=False,
           bent_elbows=False, keyframe=None) -> str:
    """MJCF text of a small humanoid robot (Z up, facing +X).  ``names[part]`` is a format
    string with ``{s}`` for the side token (``names['left']``/``names['right']``), or a list of
    them for a part made of several bodies at one origin (a 3-DOF hip)."""
    jn = [0]

    def joint(axis, rng="-90 90"):
        jn[0] += 1
        return f'<joint name="{names.get("joint", "j{n}").format(n=jn[0])}" axis="{axis}" range="{rng}"/>'

    def nest(part, side, pos, axes, inner, geom="", rng="-90 90"):
        ns = names[part] if isinstance(names[part], list) else [names[part]]
        ns = [n.format(s=names.get(side, "")) for n in ns]
        axes = (list(axes) * 3)[: len(ns)]
        out = inner
        for i in reversed(range(len(ns))):
            body_geom = geom if i == len(ns) - 1 else ""
            out = f'<body name="{ns[i]}" pos="{pos if i == 0 else "0 0 0"}">{joint(axes[i], rng)}{body_geom}{out}</body>'
        return out

    def leg(side, y):
        foot = ('<geom type="mesh" mesh="foot_mesh"/>' if mesh_feet
                else '<geom type="box" size="0.1 0.04 0.025" pos="0.04 0 -0.035"/>')
        toe = nest("toe", side, "0.14 0 -0.045", ["0 1 0"], "", '<geom type="box" size="0.02 0.04 0.015"/>',
                   "-30 60") if toes else ""
        ankle = nest("ankle", side, "0 0 -0.4", ["0 1 0", "1 0 0"], toe, foot, "-40 40")
        knee = nest("knee", side, "0 0 -0.4", ["0 1 0"], ankle,
                    '<geom type="capsule" fromto="0 0 0 0 0 -0.4" size="0.04"/>', "0 150")
        return nest("hip", side, f"0 {y} -0.08", ["0 0 1", "1 0 0", "0 1 0"], knee,
                    '<geom type="capsule" fromto="0 0 0 0 0 -0.4" size="0.05"/>')

    def arm(side, y):
        sign = 1 if y > 0 else -1
        hand_end = f'<body name="{names["hand_end"].format(s=names[side])}" pos="0 0 -0.08"/>' if "hand_end" in names else ""
        wrist = nest("wrist", side, "0.25 0 0" if bent_elbows else "0 0 -0.25", ["1 0 0"], hand_end,
                     '<geom type="box" size="0.03 0.02 0.04" pos="0 0 -0.04"/>') if wrists else ""
        fore = '0 0 0 0.25 0 0' if bent_elbows else '0 0 0 0 0 -0.25'
        elbow = nest("elbow", side, "0 0 -0.28", ["0 1 0"], wrist,
                     f'<geom type="capsule" fromto="{fore}" size="0.03"/>', "-60 120" if bent_elbows else "-150 5")
        shoulder_pos = f"0 {0.15 * sign:.2f} 0.02" if clavicle else f"0 {y} 0.28"
        out = nest("shoulder", side, shoulder_pos, ["0 1 0", "1 0 0", "0 0 1"], elbow,
                   '<geom type="capsule" fromto="0 0 0 0 0 -0.28" size="0.035"/>')
        if clavicle:
            out = nest("clavicle", side, f"0 {0.05 * sign:.2f} 0.26", ["1 0 0"], out, "", "-20 20")
        return out

    head_geom = '<geom type="sphere" size="0.1" pos="0 0 0.1"/>'
    if neck:
        head = nest("head", None, "0 0 0.08", ["0 0 1"], "", head_geom)
        head = nest("neck", None, "0 0 0.33", ["0 1 0"], head, "")
    else:
        head = '<geom type="sphere" size="0.1" pos="0 0 0.45"/>'
    torso = nest("torso", None, "0 0 0.1", ["0 1 0"], head + (arm("left", 0.2) + arm("right", -0.2) if arms else ""),
                 '<geom type="box" size="0.08 0.14 0.15" pos="0 0 0.15"/>', "-30 30")
    waist = nest("waist", None, "0 0 0.1", ["0 0 1"], torso, "", "-60 60")
    key = ""
    if keyframe:
        key = f'<keyframe><key name="{keyframe}" qpos="{" ".join(["0"] * 7)} {{rest}}"/></keyframe>'
    xml = (
        '<mujoco model="fixture"><compiler angle="degree" boundmass="0.01" boundinertia="0.0001"/>'
        f'<asset>{_MESH_FOOT if mesh_feet else ""}</asset><worldbody>'
        f'<body name="{names["pelvis"]}" pos="0 0 0.95"><freejoint/>'
        '<geom type="box" size="0.08 0.12 0.06"/>'
        f'{leg("left", 0.1)}{leg("right", -0.1)}{waist}</body></worldbody>{key}</mujoco>'
    )
    return xml


def _write(tmp_path, xml: str, name="robot.xml"):
    if "{rest}" in xml:  # a keyframe: the zero pose with the free joint's quaternion set
        import mujoco

        m = mujoco.MjModel.from_xml_string(xml.replace("<keyframe>", "<!--").replace("</keyframe>", "-->"))
        q = m.qpos0.copy()
        xml = xml.replace(f'qpos="{" ".join(["0"] * 7)} {{rest}}"', 'qpos="' + " ".join(f"{v:g}" for v in q) + '"')
    p = tmp_path / name
    p.write_text(xml)
    return p


STYLES = {
    # G1 / H1 style: left_knee_link, a hip of three bodies at one origin
    "left_knee_link": {
        "left": "left", "right": "right", "pelvis": "pelvis",
        "hip": ["{s}_hip_yaw_link", "{s}_hip_roll_link", "{s}_hip_pitch_link"],
        "knee": "{s}_knee_link", "ankle": ["{s}_ankle_pitch_link", "{s}_ankle_roll_link"],
        "toe": "{s}_toe_link", "shoulder": ["{s}_shoulder_pitch_link", "{s}_shoulder_roll_link", "{s}_shoulder_yaw_link"],
        "elbow": "{s}_elbow_link", "wrist": "{s}_wrist_roll_link", "hand_end": "{s}_hand_tip",
        "waist": "waist_yaw_link", "torso": "torso_link", "neck": "neck_link", "head": "head_link",
        "joint": "joint_{n}",
    },
    # Unitree quadruped-like segment names: l_thigh_link, l_calf_link
    "l_calf_link": {
        "left": "l", "right": "r", "pelvis": "base",
        "hip": ["{s}_hip_link", "{s}_thigh_link"], "knee": "{s}_calf_link", "ankle": "{s}_foot_link",
        "toe": "{s}_toe_link", "shoulder": ["{s}_shoulder_link", "{s}_upper_arm_link"],
        "elbow": "{s}_forearm_link", "wrist": "{s}_hand_link",
        "waist": "abdomen", "torso": "chest_link", "neck": "neck", "head": "head",
    },
    # upper case, one body per joint: L_KNEE
    "L_KNEE": {
        "left": "L", "right": "R", "pelvis": "PELVIS", "hip": "{s}_HIP", "knee": "{s}_KNEE",
        "ankle": "{s}_ANKLE", "toe": "{s}_TOE", "shoulder": "{s}_SHOULDER", "elbow": "{s}_ELBOW",
        "wrist": "{s}_WRIST", "waist": "WAIST", "torso": "TORSO", "neck": "NECK", "head": "HEAD",
        "joint": "J{n}",
    },
    # animation rig names: LeftUpLeg, LeftLeg, LeftShoulder (a clavicle) then LeftArm
    "LeftLeg": {
        "left": "Left", "right": "Right", "pelvis": "Hips", "hip": "{s}UpLeg", "knee": "{s}Leg",
        "ankle": "{s}Foot", "toe": "{s}ToeBase", "clavicle": "{s}Shoulder", "shoulder": "{s}Arm",
        "elbow": "{s}ForeArm", "wrist": "{s}Hand", "waist": "Spine", "torso": "Spine1", "neck": "Neck",
        "head": "Head",
    },
    # no usable names at all: sides by position, parts by tree position
    "anonymous": {
        "left": "a", "right": "b", "pelvis": "base", "hip": ["b1{s}", "b2{s}", "b3{s}"], "knee": "b4{s}",
        "ankle": ["b5{s}", "b6{s}"], "toe": "b7{s}", "shoulder": ["b8{s}", "b9{s}", "b10{s}"],
        "elbow": "b11{s}", "wrist": "b12{s}", "waist": "b13", "torso": "b14", "neck": "b15", "head": "b16",
    },
}

#: canonical joint -> expected body (format string, {s} = side token) per style
EXPECTED = {
    "left_knee_link": {
        "pelvis": "pelvis", "spine": "waist_yaw_link", "chest": "torso_link", "neck": "neck_link",
        "head": "head_link", "hip": "{s}_hip_yaw_link", "knee": "{s}_knee_link",
        "ankle": "{s}_ankle_roll_link", "toe": "{s}_toe_link", "shoulder": "{s}_shoulder_pitch_link",
        "elbow": "{s}_elbow_link", "wrist": "{s}_wrist_roll_link", "hand_end": "{s}_hand_tip",
    },
    "l_calf_link": {
        "pelvis": "base", "hip": "{s}_hip_link", "knee": "{s}_calf_link", "ankle": "{s}_foot_link",
        "toe": "{s}_toe_link", "shoulder": "{s}_shoulder_link", "elbow": "{s}_forearm_link",
        "wrist": "{s}_hand_link", "neck": "neck", "head": "head",
    },
    "L_KNEE": {
        "pelvis": "PELVIS", "hip": "{s}_HIP", "knee": "{s}_KNEE", "ankle": "{s}_ANKLE", "toe": "{s}_TOE",
        "shoulder": "{s}_SHOULDER", "elbow": "{s}_ELBOW", "wrist": "{s}_WRIST", "neck": "NECK", "head": "HEAD",
    },
    "LeftLeg": {
        "pelvis": "Hips", "hip": "{s}UpLeg", "knee": "{s}Leg", "ankle": "{s}Foot", "toe": "{s}ToeBase",
        "clavicle": "{s}Shoulder", "shoulder": "{s}Arm", "elbow": "{s}ForeArm", "wrist": "{s}Hand",
        "spine": "Spine", "chest": "Spine1", "neck": "Neck", "head": "Head",
    },
    "anonymous": {
        "pelvis": "base", "hip": "b1{s}", "knee": "b4{s}", "ankle": "b6{s}", "toe": "b7{s}",
        "shoulder": "b8{s}", "elbow": "b11{s}", "wrist": "b12{s}",
    },
}

_CENTER = {"pelvis", "spine", "chest", "neck", "head", "head_end"}


def _expected(style: str) -> dict[str, str]:
    names = STYLES[style]
    out = {}
    for part, body in EXPECTED[style].items():
        if part in _CENTER:
            out[part] = body
        else:
            for side in ("left", "right"):
                out[f"{side}_{part}"] = body.format(s=names[side])
    return out


def _loads(tmp_path, proposal, mjcf):
    mp = tmp_path / "proposed.map.toml"
    mp.write_text(proposal.to_toml())
    return load_character(mjcf, mp)


@pytest.mark.parametrize("style", list(STYLES))
def test_naming_styles(tmp_path, style):
    xml = _robot(STYLES[style], clavicle=style == "LeftLeg")
    mjcf = _write(tmp_path, xml)
    pr = propose_mapping(mjcf)
    got = {c: g.name for c, g in pr.joints.items()}
    for canon, body in _expected(style).items():
        assert got.get(canon) == body, (canon, got.get(canon), body, "\n".join(pr.report()))
    assert (pr.up, pr.forward) == ("Z", "X")
    ch = _loads(tmp_path, pr, mjcf)
    rest = ch.rest_positions()
    assert rest["left_hip"][1] > rest["right_hip"][1]  # left is +Y when facing +X
    assert rest["left_shoulder"][1] > rest["right_shoulder"][1]
    assert set(ch.contacts) == {"left", "right"}  # found on the feet's geoms
    if style == "anonymous":
        assert any("position" in g.why for g in pr.joints.values())


def test_robot_without_toes_wrists_or_neck(tmp_path):
    mjcf = _write(tmp_path, _robot(STYLES["left_knee_link"], toes=False, wrists=False, neck=False))
    pr = propose_mapping(mjcf)
    for canon in ("neck", "head", "left_hand_end", "left_toe_end"):
        assert canon not in pr.joints and canon in pr.left_out
    joints_table = pr.to_toml().split("[joints]")[1].split("# left out")[0]
    assert "neck" not in joints_table
    # no wrist joint: the wrist is a site at the end of the forearm's geoms (the capsule's end,
    # 25 cm below the elbow), so the forearm's direction is tracked
    for side in ("left", "right"):
        w = pr.joints[f"{side}_wrist"]
        assert w.kind == "site" and pr.sites[w.name][0] == f"{side}_elbow_link"
        assert np.allclose(pr.sites[w.name][1], (0.0, 0.0, -0.25), atol=0.005)  # the end of the capsule
    # a rigid foot still has a ball: a site on the ankle's body, 3/4 of the sole from the heel
    toe = pr.joints["left_toe"]
    assert toe.kind == "site" and pr.sites[toe.name][0] == "left_ankle_roll_link"
    ch = _loads(tmp_path, pr, mjcf)
    assert "neck" not in ch.tracked and ch.tracked["left_wrist"].name == "left_forearm_end"
    assert ch.tracked["left_elbow"].name == "left_elbow_link"
    rest = ch.rest_positions()
    assert 0.08 < rest["left_toe"][0] - rest["left_ankle"][0] < 0.12 and 0.0 < rest["left_toe"][2] < 0.03

    # and it retargets: the walk's legs follow the actor's
    from physmocap import load_motion, retarget
    from physmocap.metrics.fidelity import trajectory_fidelity

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traj = retarget(load_motion("example"), ch, progress=False, end=90)
    fid = trajectory_fidelity(traj)
    assert np.all(np.isfinite(traj.qpos))
    assert max(fid.segments[s].median_deg for s in ("left_thigh", "right_thigh", "left_shank", "right_shank")) < 12.0


def test_mesh_feet_and_renamed_bodies(tmp_path):
    """Mesh feet (the contact points come from the mesh's hull) and names in upper case."""
    mjcf = _write(tmp_path, _robot(STYLES["L_KNEE"], mesh_feet=True))
    ch = _loads(tmp_path, propose_mapping(mjcf), mjcf)
    import mujoco

    d = mujoco.MjData(ch.model)
    d.qpos[:] = ch.rest_qpos
    mujoco.mj_kinematics(ch.model, d)
    heel = d.site_xpos[ch.model.site(ch.contacts["left"][0]).id]
    toe = d.site_xpos[ch.model.site(ch.contacts["left"][-1]).id]
    assert toe[0] - heel[0] == pytest.approx(0.22, abs=0.01)  # heel of the mesh to the toe box and abs(heel[2]) < 1e-3


def test_pelvis_below_a_free_trunk_and_names_on_joints(tmp_path):
    """Booster-T1-like: the free body is the trunk (arms, head), the legs hang from a waist body
    below it; arm bodies are AL1..AL4 (the parts are in the joints' names); rigid hands."""
    mjcf = REPO / "tests" / "fixtures" / "robot_trunk_root.xml"
    pr = propose_mapping(mjcf)
    got = {c: g.name for c, g in pr.joints.items()}
    assert got["pelvis"] == "Waist" and got["spine"] == "Trunk"
    assert (got["neck"], got["head"]) == ("H1", "H2")
    assert (got["left_shoulder"], got["left_elbow"], got["left_wrist"]) == ("AL2", "AL3", "left_hand_link")
    assert (got["right_hip"], got["right_knee"], got["right_ankle"]) == ("Hip_Pitch_Right", "Shank_Right", "right_foot_link")
    ch = _loads(tmp_path, pr, mjcf)
    from physmocap import load_motion, retarget

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traj = retarget(load_motion("example"), ch, progress=False, end=30)
    assert np.all(np.isfinite(traj.qpos))


def test_y_up_model_facing_z(tmp_path):
    """The stilt biped fixture: Y up (gravity), facing +Z, sides as suffixes (thighL)."""
    mjcf = REPO / "tests" / "fixtures" / "biped.xml"
    pr = propose_mapping(mjcf)
    assert (pr.up, pr.forward) == ("Y", "Z")
    assert pr.joints["left_knee"].name == "shinL" and pr.joints["right_hip"].name == "thighR"
    ch = _loads(tmp_path, pr, mjcf)
    rest = ch.rest_positions()
    assert rest["left_hip"][1] > rest["right_hip"][1] and rest["pelvis"][2] > rest["left_knee"][2]


def test_rest_pose_keyframe_or_straightened_zero_pose(tmp_path):
    names = STYLES["left_knee_link"]
    bent = propose_mapping(_write(tmp_path, _robot(names, bent_elbows=True), "bent.xml"))
    assert bent.rest_keyframe is None and "zero pose" in bent.rest_note
    elbows = {k: v for k, v in bent.rest_joints.items()}
    assert len(elbows) == 2 and all(abs(abs(v) - 90) <= 1 for v in elbows.values()), elbows
    ch = _loads(tmp_path, bent, tmp_path / "bent.xml")
    rest = ch.rest_positions()
    arm = rest["left_wrist"] - rest["left_shoulder"]
    assert arm[2] < -0.5  # straightened: the wrist hangs below the shoulder

    home = propose_mapping(_write(tmp_path, _robot(names, keyframe="home"), "home.xml"))
    assert home.rest_keyframe == "home" and not home.rest_joints and "'home'" in home.rest_note
    assert '[rest]\nkeyframe = "home"' in home.to_toml()


def test_zero_pose_outside_a_range_is_clamped(tmp_path):
    """A knee whose range excludes zero (5.73 to 150 degrees): the rest pose takes its nearest end."""
    xml = _robot(STYLES["L_KNEE"]).replace('axis="0 1 0" range="0 150"', 'axis="0 1 0" range="5.73 150"')
    mjcf = _write(tmp_path, xml)
    pr = propose_mapping(mjcf)
    knees = {k: v for k, v in pr.rest_joints.items()}
    assert len(knees) == 2 and all(v == pytest.approx(5.8) for v in knees.values()), knees
    assert "nearest end of their range" in pr.rest_note
    _loads(tmp_path, pr, mjcf)  # within range once written and read back


def test_name_sides():
    for n in ("left_knee_link", "l_calf_link", "L_KNEE", "LeftLeg", "knee_l", "LKnee", "lfemur", "Left Arm"):
        assert name_side(n) == "left", n
    for n in ("right_knee_link", "r_calf_link", "R_KNEE", "RightLeg", "knee_R", "rfemur"):
        assert name_side(n) == "right", n
    for n in ("pelvis", "torso_link", "link3", "lower_leg", "Leg"):
        assert name_side(n) is None, n


# -- the command -----------------------------------------------------------------------------


def test_cli_stdout_and_guesses_on_stderr(tmp_path, capsys):
    mjcf = _write(tmp_path, _robot(STYLES["l_calf_link"]))
    assert main(["character", "init", str(mjcf)]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("# Mapping proposed") and "[joints]" in out
    assert "left_knee" in err and "-> body:l_calf_link" in err and "name 'calf'" in err
    assert "left out:" in err and "rest pose: zero pose" in err and "checked: loads" in err


def test_cli_output_file_refuses_to_overwrite(tmp_path, capsys):
    mjcf = _write(tmp_path, _robot(STYLES["L_KNEE"]))
    out = tmp_path / "robot.map.toml"
    assert main(["character", "init", str(mjcf), "-o", str(out)]) == 0
    first = out.read_text()
    out.write_text("# mine\n")
    capsys.readouterr()
    assert main(["character", "init", str(mjcf), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("physmocap: error: ") and "--force" in err and err.count("\n") == 1
    assert out.read_text() == "# mine\n"
    assert main(["character", "init", str(mjcf), "-o", str(out), "--force"]) == 0
    assert out.read_text() == first
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary left
    # found beside the model by its name: no --map needed
    assert load_character(mjcf).tracked["left_knee"].name == "L_KNEE"


@pytest.mark.parametrize(
    "xml, message",
    [
        ('<mujoco><worldbody><body name="a"><geom size="0.1"/></body></worldbody></mujoco>', "no free joint"),
        ('<mujoco><worldbody><body name="a"><freejoint/><geom size="0.1"/><body name="b" pos="0 0 0.3">'
         '<joint/><geom size="0.05"/></body></body></worldbody></mujoco>', "no recognisable legs"),
        ('<mujoco><worldbody><body name="a"><freejoint/><geom size="0.1"/>'
         '<body name="b" pos="0 0 -0.5"><joint/><geom size="0.05"/></body></body></worldbody></mujoco>',
         "no recognisable legs"),
        ('<mujoco><worldbody><body name="a"', "MuJoCo cannot load this MJCF"),
        ("not xml at all", "MuJoCo cannot load this MJCF"),
    ],
)
def test_cli_bad_models_one_line(tmp_path, capsys, xml, message):
    mjcf = tmp_path / "bad.xml"
    mjcf.write_text(xml)
    assert main(["character", "init", str(mjcf)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.startswith(f"physmocap: error: {mjcf}: ") and message in err and err.count("\n") == 1, err


def test_retarget_onto_a_model_without_legs_says_why(tmp_path, capsys):
    """Before: retargeting onto a model with no legs and no mapping file listed eleven
    unmapped joints and not why none could be proposed (``character init`` said it)."""
    mjcf = tmp_path / "nolegs.xml"
    mjcf.write_text('<mujoco><worldbody><body name="a"><freejoint/><geom size="0.1"/><body name="b" pos="0 0 0.3">'
                    '<joint/><geom size="0.05"/></body></body></worldbody></mujoco>')
    assert main(["retarget", "example", "--character", str(mjcf), "-o", str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err
    assert "no recognisable legs" in err and err.count("\n") == 1, err
    assert not (tmp_path / "x.npz").exists()


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        propose_mapping(tmp_path / "nope.xml")


# -- the Unitree G1 (shared data) ---------------------------------------------------------------


@pytest.fixture(scope="module")
def g1_proposal():
    if not G1.exists():
        pytest.skip(f"the Unitree G1 model is not here: {G1} (../shared absent)")
    return propose_mapping(G1)


MAJOR = ("pelvis", "spine") + tuple(
    f"{side}_{part}" for side in ("left", "right")
    for part in ("hip", "knee", "ankle", "toe", "shoulder", "elbow", "wrist", "hand_end")
)


def test_g1_major_joints_match_the_bundled_mapping(g1_proposal):
    from physmocap.models.mapping import read_mapping

    bundled = read_mapping(G1_BUNDLED).joints
    got = g1_proposal.joints
    for canon in MAJOR:
        assert got[canon].name == bundled[canon].name, canon
    assert "neck" in g1_proposal.left_out  # the G1 has no neck joint
    # the zero pose bends the elbows: straightened (the bundled file, by hand: 90 degrees)
    assert set(g1_proposal.rest_joints) == {"left_elbow_joint", "right_elbow_joint"}
    assert all(75 <= v <= 95 for v in g1_proposal.rest_joints.values())


def test_g1_proposal_retargets_like_the_bundled_mapping(g1_proposal, tmp_path):
    import mujoco

    from physmocap import load_motion, retarget

    mp = tmp_path / "g1.map.toml"
    mp.write_text(g1_proposal.to_toml())
    motion = load_motion(shared_file("pymo_walk.bvh"))
    trajs = []
    for m in (mp, G1_BUNDLED):
        ch = load_character(G1, m)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            trajs.append((ch, retarget(motion, ch, progress=False, end=60, plant=False)))
    (cp, tp), (cb, tb) = trajs
    assert np.all(np.isfinite(tp.qpos)) and tp.qpos.shape == tb.qpos.shape
    dp, db = mujoco.MjData(cp.model), mujoco.MjData(cb.model)
    worst = 0.0
    for qp, qb in zip(tp.qpos, tb.qpos):
        dp.qpos[:], db.qpos[:] = qp, qb
        mujoco.mj_kinematics(cp.model, dp)
        mujoco.mj_kinematics(cb.model, db)
        for canon in MAJOR:
            b = cb.tracked[canon].name
            worst = max(worst, float(np.linalg.norm(dp.body(b).xpos - db.body(b).xpos)))
    # 2.1 cm since stop 37: the bundled mapping's neck follows the actor's trunk line from the
    # pelvis joint (the G1's 13 cm above its hip centres); the proposal, which has no neck, turns
    # its torso with the actor's spine (under 1 cm when the line ran from the hip centres)
    assert worst < 0.025, f"proposed vs bundled mapping: bodies {worst * 100:.1f} cm apart"


def test_g1_cli_writes_a_mapping_that_retargets(g1_proposal, tmp_path, capsys):
    out = tmp_path / "g1.map.toml"
    assert main(["character", "init", str(G1), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "left_knee       -> body:left_knee_link" in err and "neck (no head joint)" in err
    npz = tmp_path / "walk.npz"
    assert main(["retarget", str(shared_file("pymo_walk.bvh")), "--character", str(G1), "--map", str(out),
                 "--end", "60", "--no-plant", "--quiet", "-o", str(npz)]) == 0
    assert npz.exists()


def test_model_without_a_mapping_file_loads_with_the_proposal(tmp_path):
    """Issue 13: a robot with no mapping file beside it retargets with the proposed mapping
    (and one warning saying so), instead of refusing to load."""
    import shutil

    import physmocap
    from physmocap.models import load_character

    src = REPO / "tests" / "fixtures" / "robot_trunk_root.xml"
    model = tmp_path / "my_robot.xml"
    shutil.copy(src, model)
    with pytest.warns(Warning, match="no mapping file found: using the mapping `physmocap character init` proposes"):
        ch = load_character(model)
    assert ch.mapping_proposed and ch.map_path is None
    assert {"pelvis", "left_knee", "right_ankle"} <= set(ch.tracked)
    with warnings.catch_warnings():  # the retarget's own diagnostics are not under test here
        warnings.simplefilter("ignore")
        traj = physmocap.retarget(physmocap.load_motion("example"), ch, end=30, progress=False, plant=False)
    assert np.isfinite(traj.qpos).all()


# -- real robots' shapes that the styles above lack (issue 13, Menagerie models) ------------------


def _offset_robot() -> str:
    """A humanoid with the Unitree H1's hip (yaw and roll bodies inward, the pitch body 11 cm
    out, the thigh hung below it) and the Booster T1's arm (the body named ``elbow`` turns
    about the upper arm; the forearm, named ``hand``, bends at its root; no wrist)."""

    def leg(s, sg):
        return (
            f'<body name="{s}_hip_yaw_link" pos="0 {0.09 * sg} -0.08"><joint name="{s}_hip_yaw" axis="0 0 1" range="-30 30"/>'
            f'<body name="{s}_hip_roll_link" pos="0.04 0 0"><joint name="{s}_hip_roll" axis="1 0 0" range="-30 30"/>'
            f'<body name="{s}_hip_pitch_link" pos="0 {0.11 * sg} 0"><joint name="{s}_hip_pitch" axis="0 1 0" range="-90 90"/>'
            '<geom type="capsule" fromto="0 0 0 0 0 -0.4" size="0.05"/>'
            f'<body name="{s}_knee_link" pos="0 0 -0.4"><joint name="{s}_knee" axis="0 1 0" range="0 150"/>'
            '<geom type="capsule" fromto="0 0 0 0 0 -0.4" size="0.04"/>'
            f'<body name="{s}_ankle_link" pos="0 0 -0.4"><joint name="{s}_ankle" axis="0 1 0" range="-40 40"/>'
            '<geom type="box" size="0.1 0.04 0.025" pos="0.04 0 -0.035"/>'
            "</body></body></body></body></body>"
        )

    def arm(s, sg):
        return (
            f'<body name="{s}_arm1" pos="0 {0.2 * sg} 0.3"><joint name="{s}_shoulder_pitch" axis="0 1 0" range="-180 60"/>'
            f'<body name="{s}_arm2" pos="0 {0.04 * sg} 0"><joint name="{s}_shoulder_roll" axis="1 0 0" range="-90 90"/>'
            '<geom type="sphere" size="0.04"/>'
            f'<body name="{s}_elbow_twist" pos="0 0 -0.06"><joint name="{s}_elbow_yaw" axis="0 0 1" range="-90 90"/>'
            '<geom type="capsule" fromto="0 0 0 0 0 -0.16" size="0.03"/>'
            f'<body name="{s}_hand_link" pos="0 0 -0.16"><joint name="{s}_elbow_pitch" axis="0 1 0" range="-120 0"/>'
            '<geom type="capsule" fromto="0 0 0 0 0 -0.22" size="0.03"/>'
            "</body></body></body></body>"
        )

    return (
        '<mujoco model="offset"><compiler angle="degree" boundmass="0.01" boundinertia="0.0001"/><worldbody>'
        '<body name="pelvis" pos="0 0 0.95"><freejoint/><geom type="box" size="0.08 0.12 0.06"/>'
        f'{leg("left", 1)}{leg("right", -1)}'
        '<body name="torso_link" pos="0 0 0.1"><joint name="waist" axis="0 0 1" range="-60 60"/>'
        '<geom type="box" size="0.08 0.14 0.15" pos="0 0 0.2"/>'
        f'{arm("left", 1)}{arm("right", -1)}</body></body></worldbody></mujoco>'
    )


def test_offset_hip_takes_the_body_over_the_knee(tmp_path):
    """Unitree H1: the hip's three axes meet at the yaw body, 11 cm inward of the thigh; with
    the hip there, hip -> knee leant 16 degrees and the knees were pulled in (thighs 11-14
    degrees off the actor on the walks).  The hip is the body over the knee."""
    mjcf = _write(tmp_path, _offset_robot(), "offset.xml")
    pr = propose_mapping(mjcf)
    for side in ("left", "right"):
        assert pr.joints[f"{side}_hip"].name == f"{side}_hip_pitch_link", pr.joints[f"{side}_hip"]
        assert "over the knee" in pr.joints[f"{side}_hip"].why
    ch = _loads(tmp_path, pr, mjcf)
    rest = ch.rest_positions()
    d = rest["left_knee"] - rest["left_hip"]
    assert np.hypot(d[0], d[1]) < 1e-6  # the thigh straight down in the rest pose


def test_twisting_elbow_gives_way_to_the_bending_hinge(tmp_path):
    """Booster T1: the body named elbow turns about the upper arm and the forearm (named hand)
    bends at its root.  Tracked as named, the upper arms were 21-29 degrees off the actor and
    the forearm swung out.  The elbow is the hinge that bends the arm; with no wrist beyond
    it, the wrist is a site at the end of the forearm's geoms."""
    mjcf = _write(tmp_path, _offset_robot(), "offset.xml")
    pr = propose_mapping(mjcf)
    for side in ("left", "right"):
        e, w = pr.joints[f"{side}_elbow"], pr.joints[f"{side}_wrist"]
        assert e.name == f"{side}_hand_link" and "bends the arm" in e.why, e
        assert w.kind == "site" and pr.sites[w.name][0] == f"{side}_hand_link"
        assert np.allclose(pr.sites[w.name][1], (0.0, 0.0, -0.22), atol=0.005)
        assert pr.joints[f"{side}_shoulder"].name in (f"{side}_arm1", f"{side}_arm2")
    ch = _loads(tmp_path, pr, mjcf)
    rest = ch.rest_positions()
    assert rest["left_elbow"][2] - rest["left_wrist"][2] == pytest.approx(0.22, abs=0.005)
    from physmocap import load_motion, retarget
    from physmocap.metrics.fidelity import trajectory_fidelity

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traj = retarget(load_motion("example"), ch, progress=False, end=90)
    fid = trajectory_fidelity(traj)
    worst = max(fid.segments[s].median_deg for s in fid.segments if "arm" in s or "thigh" in s)
    assert worst < 12.0, {s: round(v.median_deg, 1) for s, v in fid.segments.items()}


def _atlas_like() -> str:
    """Boston Dynamics Atlas's naming: every leg joint ``l_leg_*``, every arm joint ``l_arm_*``
    (the limb, not a part), bodies ``uglut``/``lglut``/``uleg``/``lleg``/``talus``/``foot`` and
    ``clav``/``scap``/``uarm``/``larm``/``ufarm``/``lfarm``/``hand``; the arm lifts at ``scap``
    and ``uarm``, 12 cm below it, only twists the upper arm."""

    def body(name, pos, joint, axis, inner="", geom=""):
        return f'<body name="{name}" pos="{pos}"><joint name="{joint}" axis="{axis}" range="-90 90"/>{geom}{inner}</body>'

    def leg(s, sg):
        foot = body(f"{s}_talus", "0 0 -0.4", f"{s}_leg_aky", "0 1 0",
                    body(f"{s}_foot", "0 0 0", f"{s}_leg_akx", "1 0 0", "",
                         '<geom type="box" size="0.1 0.05 0.02" pos="0.04 0 -0.05"/>'))
        knee = body(f"{s}_lleg", "-0.03 0 -0.4", f"{s}_leg_kny", "0 1 0", foot,
                    '<geom type="capsule" fromto="0 0 0 0 0 -0.4" size="0.04"/>')
        return body(f"{s}_uglut", f"0 {0.09 * sg} -0.05", f"{s}_leg_hpz", "0 0 1",
                    body(f"{s}_lglut", "0 0 0", f"{s}_leg_hpx", "1 0 0",
                         body(f"{s}_uleg", f"0.03 {0.02 * sg} -0.06", f"{s}_leg_hpy", "0 1 0", knee,
                              '<geom type="capsule" fromto="0 0 0 -0.03 0 -0.4" size="0.05"/>')))

    def arm(s, sg):
        hand = body(f"{s}_ufarm", "0 0 -0.28", f"{s}_arm_uwy", "0 0 1",
                    body(f"{s}_lfarm", "0 0 0", f"{s}_arm_mwx", "1 0 0",
                         body(f"{s}_hand", "0 0 0", f"{s}_arm_lwy", "0 0 1", "",
                              '<geom type="box" size="0.03 0.02 0.05" pos="0 0 -0.06"/>')))
        larm = body(f"{s}_larm", "0 0 -0.16", f"{s}_arm_elx", "0 1 0", hand,
                    '<geom type="capsule" fromto="0 0 0 0 0 -0.28" size="0.03"/>')
        uarm = body(f"{s}_uarm", "0 0 -0.12", f"{s}_arm_ely", "0 0 1", larm,
                    '<geom type="capsule" fromto="0 0 0 0 0 -0.16" size="0.035"/>')
        return body(f"{s}_clav", f"0 {0.15 * sg} 0.45", f"{s}_arm_shz", "0 0 1",
                    body(f"{s}_scap", f"0 {0.08 * sg} -0.05", f"{s}_arm_shx", "1 0 0", uarm))

    return (
        '<mujoco model="atlaslike"><compiler angle="degree" boundmass="0.01" boundinertia="0.0001"/><worldbody>'
        '<body name="pelvis" pos="0 0 1.0"><freejoint/><geom type="box" size="0.08 0.12 0.06"/>'
        f'{leg("l", 1)}{leg("r", -1)}'
        '<body name="utorso" pos="0 0 0.1"><joint name="back_bkz" axis="0 0 1" range="-30 30"/>'
        '<geom type="box" size="0.1 0.15 0.2" pos="0 0 0.25"/>'
        f'{arm("l", 1)}{arm("r", -1)}</body></body></worldbody></mujoco>'
    )


def test_limb_wide_names_and_abbreviations(tmp_path):
    """Atlas: ``leg`` in every leg joint's name made every leg body a knee (the knee went to the
    thigh's body and the rest pose bent the hips 41 degrees to straighten that 'knee'); ``arm``
    in every arm joint's name, every arm body a shoulder.  A keyword on every articulated body
    of a chain names the limb and tells no part; ``uleg``/``lleg``/``uarm``/``larm`` are the
    upper and lower leg and arm; the shoulder is where the arm's hinges meet (``scap``)."""
    mjcf = _write(tmp_path, _atlas_like(), "atlaslike.xml")
    pr = propose_mapping(mjcf)
    want = {"hip": "{s}_uleg", "knee": "{s}_lleg", "ankle": "{s}_foot", "shoulder": "{s}_scap",
            "elbow": "{s}_larm", "wrist": "{s}_hand"}
    for side, s in (("left", "l"), ("right", "r")):
        got = {part: pr.joints[f"{side}_{part}"].name for part in want}
        assert got == {part: b.format(s=s) for part, b in want.items()}, got
    assert not any("_leg_" in j for j in pr.rest_joints), pr.rest_joints  # no hip bent to 'straighten' a thigh
    _loads(tmp_path, pr, mjcf)


# -- robots without arms (issue 13: joints the robot does not have are optional) -------------

_ARM_JOINTS = tuple(f"{side}_{part}" for side in ("left", "right")
                    for part in ("clavicle", "shoulder", "elbow", "wrist", "hand_end"))


@pytest.mark.parametrize("style", ["left_knee_link", "L_KNEE", "anonymous"])
def test_armless_robot_maps_legs_pelvis_and_trunk(tmp_path, style):
    """Before: "no recognisable arms", exit 2.  A legs-only biped with a waist, a torso and a
    head gets its legs, pelvis and trunk; the arms are left out and said to be."""
    mjcf = _write(tmp_path, _robot(STYLES[style], arms=False))
    pr = propose_mapping(mjcf)
    got = {c: g.name for c, g in pr.joints.items()}
    for canon, body in _expected(style).items():
        if canon not in _ARM_JOINTS and canon not in ("neck", "head"):
            assert got.get(canon) == body, (canon, got.get(canon), body, "\n".join(pr.report()))
    names = STYLES[style]
    if style != "anonymous":
        assert (got.get("spine"), got.get("chest")) == (names["waist"], names["torso"])
        assert (got["neck"], got["head"]) == (names["neck"], names["head"])
    else:  # with no arms, only a name tells the head from the chest: the whole trunk is spine to chest
        assert (got.get("spine"), got.get("chest")) == (names["waist"], names["head"])
    assert not set(_ARM_JOINTS) & set(pr.joints)
    assert all(pr.left_out[c] == "no arms" for c in _ARM_JOINTS)
    assert any(n.startswith("no arms: the arms of the actor are not tracked") for n in pr.notes)
    ch = _loads(tmp_path, pr, mjcf)  # unedited
    from physmocap.models.character import untracked_limbs

    assert untracked_limbs(ch.tracked) == ("left_arm", "right_arm")
    assert set(ch.contacts) == {"left", "right"}


def test_armless_robot_retargets_the_legs(tmp_path):
    """The proposal of a legs-only robot retargets the walk: legs within 10 degrees of the
    actor's (median), feet on the floor, no arm figure in the fidelity."""
    from physmocap import load_motion, retarget
    from physmocap.metrics.fidelity import trajectory_fidelity

    mjcf = _write(tmp_path, _robot(STYLES["left_knee_link"], arms=False))
    ch = _loads(tmp_path, propose_mapping(mjcf), mjcf)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traj = retarget(load_motion("example"), ch, progress=False, end=120)
    fid = trajectory_fidelity(traj)
    assert np.all(np.isfinite(traj.qpos))
    assert set(fid.segments) == {"torso", "left_thigh", "right_thigh", "left_shank", "right_shank"}
    assert fid.worst_segment_median_deg < 10.0, fid.segments
    assert fid.share_any_over_45 == 0.0


def test_armless_robot_cli_init_retarget_and_report(tmp_path, capsys):
    """`character init` says what it did not find; `retarget` runs with the proposed file and
    without any, and its report names the limbs it does not track."""
    import json

    mjcf = _write(tmp_path, _robot(STYLES["L_KNEE"], arms=False), "legs.xml")
    out = tmp_path / "legs.toml"
    assert main(["character", "init", str(mjcf), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "note: no arms: the arms of the actor are not tracked" in err and "checked: loads" in err
    assert "left_shoulder" not in out.read_text().split("[joints]")[1].split("# left out")[0]
    for extra in (["--map", str(out)], []):
        report = tmp_path / "r.json"
        csv = tmp_path / "walk.csv"
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            assert main(["retarget", "example", "--character", str(mjcf), *extra, "--end", "40", "--quiet",
                         "--format", "robot-csv", "-o", str(csv), "--report", str(report)]) == 0
        told = any("no arms: the actor's are not tracked" in str(w.message) for w in said)
        assert told == (not extra), [str(w.message) for w in said]
        rep = json.loads(report.read_text())
        assert rep["character"]["untracked_limbs"] == ["left_arm", "right_arm"]
        assert not any("arm" in seg for seg in rep["fidelity"]["segments"])
        assert csv.exists()


def _small_biped(torso_joint: bool = False) -> str:
    """A legs-only biped shaped like the Berkeley Humanoid (Menagerie): the free-joint trunk
    carries two legs whose hip yaw, roll and pitch hinges sit on bodies at separate origins,
    names that tell neither side nor part (``ll_hr``...``ll_faa``), an ankle 5 cm above the
    sole, no arms and no head."""
    def leg(s: str, y: float) -> str:
        return (
            f'<body name="l{s}_hr" pos="0 {y} 0"><joint name="L{s.upper()}_HR" axis="0 0 1" range="-35 35"/>'
            f'<body name="l{s}_haa" pos="-0.035 0 -0.057"><joint name="L{s.upper()}_HAA" axis="1 0 0" range="-35 35"/>'
            f'<geom type="cylinder" size="0.05 0.025" quat="0.707 0 0.707 0"/>'
            f'<body name="l{s}_hfe" pos="0.045 {0.016 if y > 0 else -0.016} -0.046">'
            f'<joint name="L{s.upper()}_HFE" axis="0 1 0" range="-100 30"/>'
            f'<geom type="capsule" fromto="0 0 0 0 0 -0.2" size="0.04"/>'
            f'<body name="l{s}_kfe" pos="0 {0.074 if y > 0 else -0.074} -0.22">'
            f'<joint name="L{s.upper()}_KFE" axis="0 1 0" range="0 120"/>'
            f'<geom type="box" size="0.015 0.02 0.08" pos="0 0 -0.08"/>'
            f'<body name="l{s}_ffe" pos="0 0 -0.18"><joint name="L{s.upper()}_FFE" axis="0 1 0" range="-30 40"/>'
            f'<body name="l{s}_faa" pos="0.017 0 0"><joint name="L{s.upper()}_FAA" axis="1 0 0" range="-30 30"/>'
            f'<geom type="box" size="0.08 0.0275 0.006" pos="0.01 0 -0.045"/>'
            "</body></body></body></body></body></body>"
        )
    waist = ('<body name="torso_link" pos="0 0 0.05"><joint name="waist_yaw" axis="0 0 1" range="-60 60"/>'
             '<geom type="box" size="0.09 0.12 0.1" pos="0.02 0 0.12"/></body>') if torso_joint else \
        '<geom type="box" size="0.09 0.125 0.125" pos="0.02 0 0.12"/>'
    return (
        '<mujoco model="small_biped"><compiler angle="degree" boundmass="0.01" boundinertia="0.0001"/><worldbody>'
        f'<body name="torso" pos="0 0 0.6"><freejoint/>{waist}{leg("l", 0.07)}{leg("r", -0.07)}</body>'
        "</worldbody></mujoco>"
    )


def test_legs_only_biped_with_spread_hip_and_short_shank(tmp_path):
    """Berkeley-Humanoid-like (Menagerie): no arms, no names that tell sides or parts, hip
    yaw/roll/pitch on bodies at separate origins, an ankle 5 cm above the sole.  Before: the
    knee was the hip's pitch body and the ankle the knee (the shank's end was taken for a toe
    joint level with the sole)."""
    mjcf = tmp_path / "small.xml"
    mjcf.write_text(_small_biped())
    pr = propose_mapping(mjcf)
    got = {c: g.name for c, g in pr.joints.items()}
    for side, s in (("left", "l"), ("right", "r")):
        assert got[f"{side}_hip"] == f"l{s}_hfe"  # nearest the hip's axes' meeting point
        assert got[f"{side}_ankle"] == f"l{s}_faa"
        assert pr.joints[f"{side}_toe"].kind == "site"  # the ball of the rigid foot
        # the knee body's origin sits 7.4 cm out along its hinge: a site on the hip-ankle line
        knee = pr.joints[f"{side}_knee"]
        assert knee.kind == "site" and pr.sites[knee.name][0] == f"l{s}_kfe"
    assert got["pelvis"] == "torso" and "spine" not in got
    ch = _loads(tmp_path, pr, mjcf)
    rest = ch.rest_positions()
    assert rest["left_hip"][2] > rest["left_knee"][2] > rest["left_ankle"][2] > 0.04
    data = ch.rest_data()
    for side, s in (("left", "l"), ("right", "r")):  # the knee on the hip-ankle line, its body 7 cm off
        h, k, a = (rest[f"{side}_{x}"] for x in ("hip", "knee", "ankle"))
        body = data.body(f"l{s}_kfe").xpos
        assert np.linalg.norm(np.cross(k - h, a - h)) / np.linalg.norm(a - h) < 0.01
        assert np.linalg.norm(np.cross(body - h, a - h)) / np.linalg.norm(a - h) > 0.03
    # and the legs follow the actor's: 4-5 degrees off (median) on the bundled walk, 10-11 with
    # the knee bodies tracked
    from physmocap import load_motion, retarget
    from physmocap.metrics.fidelity import trajectory_fidelity

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fid = trajectory_fidelity(retarget(load_motion("example"), ch, progress=False, end=120))
    assert set(fid.segments) == {"left_thigh", "right_thigh", "left_shank", "right_shank"}
    assert fid.worst_segment_median_deg < 7.0, fid.segments

    torso = tmp_path / "small_torso.xml"
    torso.write_text(_small_biped(torso_joint=True))
    pr = propose_mapping(torso)
    assert pr.joints["spine"].name == "torso_link" and "chest" not in pr.joints


def test_an_arm_is_mapped_whole_or_not_at_all(tmp_path):
    """The loader's rule for optional limbs: an arm is its shoulder and elbow, both or neither;
    a wrist needs its arm.  One arm alone is a character (its other arm not tracked)."""
    from physmocap.models.character import untracked_limbs

    mjcf = _write(tmp_path, _robot(STYLES["L_KNEE"], toes=False))
    text = propose_mapping(mjcf).to_toml()
    mp = tmp_path / "m.map.toml"

    def without(*canons):
        keep = [ln for ln in text.splitlines() if not any(ln.startswith(c + " ") for c in canons)]
        mp.write_text("\n".join(keep) + "\n")
        return mp

    with pytest.raises(MappingError, match=r"left_shoulder mapped without left_elbow: the left arm is tracked "
                                           r"from its shoulder and elbow") as exc:
        load_character(mjcf, without("left_elbow"))
    assert str(mp) in str(exc.value) and exc.value.line is not None
    with pytest.raises(MappingError, match="right_wrist mapped without the right arm"):
        load_character(mjcf, without("right_shoulder", "right_elbow", "right_hand_end"))
    ch = load_character(mjcf, without("right_shoulder", "right_elbow", "right_wrist"))
    assert untracked_limbs(ch.tracked) == ("right_arm",) and "left_elbow" in ch.tracked
    from physmocap import load_motion, retarget

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traj = retarget(load_motion("example"), ch, progress=False, end=20)
    assert np.all(np.isfinite(traj.qpos))


@pytest.mark.parametrize("key, used", [("stand", "stand"), ("Standing", "Standing"), ("home_pose", "home_pose"),
                                       ("crouch", None)])
def test_rest_pose_from_a_keyframe_named_like_standing(tmp_path, key, used):
    """Apptronik Apollo's standing keyframe is ``stand``: before, only ``rest`` and ``home``
    were taken and Apollo got the zero pose.  A keyframe whose name says nothing of standing
    is not a rest pose."""
    pr = propose_mapping(_write(tmp_path, _robot(STYLES["L_KNEE"], keyframe=key)))
    assert pr.rest_keyframe == used
    if used is None:
        assert "zero pose" in pr.rest_note and "'stand'" in pr.rest_note
    else:
        assert pr.rest_note == f"keyframe {used!r}" and f'[rest]\nkeyframe = "{used}"' in pr.to_toml()
        # the character says which pose it stands in (`character info`)
        assert _loads(tmp_path, pr, tmp_path / "robot.xml").rest_pose == f"keyframe {used!r}"


def test_character_says_where_its_rest_pose_comes_from(tmp_path, capsys):
    bent = _write(tmp_path, _robot(STYLES["left_knee_link"], bent_elbows=True), "bent.xml")
    ch = _loads(tmp_path, propose_mapping(bent), bent)
    assert ch.rest_pose == "zero pose (no keyframe), 2 joint(s) set by [rest.joints]"
    assert load_character("robot").rest_pose == "keyframe 'home'"
    assert main(["character", "info", "humanoid"]) == 0
    assert "rest pose  keyframe 'rest'\n" in capsys.readouterr().out


def test_arms_without_elbows_are_left_out(tmp_path):
    """Rigid arms on a shoulder (no joint beyond it, no names): no elbow to track, so the arms
    are left out, said in a note, and the rest is a character (before: "no recognisable arms")."""
    import re

    xml = _robot(STYLES["anonymous"], wrists=False)
    xml = re.sub(r'(<body name="b11[ab]" pos="[^"]*">)<joint[^>]*/>', r"\1", xml)  # the elbows welded
    mjcf = _write(tmp_path, xml)
    pr = propose_mapping(mjcf)
    assert not set(_ARM_JOINTS) & set(pr.joints), pr.report()
    assert any(n.startswith("no arms: the arms of the actor are not tracked (cannot tell the elbow")
               for n in pr.notes), pr.notes
    from physmocap.models.character import untracked_limbs

    assert untracked_limbs(_loads(tmp_path, pr, mjcf).tracked) == ("left_arm", "right_arm")
