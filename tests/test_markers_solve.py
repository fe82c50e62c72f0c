"""Optical markers (issue 11, second part): functional joint centres, marker-driven IK, ``physmocap solve``."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from physmocap.cli import main
from physmocap.errors import InputError
from physmocap.markers.functional import functional_joint_centres, score_fit, sphere_fit
from physmocap.markers.markerset import detect_marker_set
from physmocap.markers.recording import MarkerRecording
from physmocap.sources.trc import read_trc_markers

SHARED = Path(__file__).parents[1].parent / "shared" / "data"


def _shared(name: str) -> Path:
    p = SHARED / name
    if not p.exists():
        pytest.skip(f"real recording {name} not found: ../shared/data is absent ({SHARED})")
    return p


def _rot(axis: str, deg) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler(axis, np.atleast_1d(deg)[:, None], degrees=True).as_matrix()


#: True hip centres in the pelvis frame (x forward, y left, z up), 2-3 cm off Harrington's
#: regression for this pelvis (W 0.25, D 0.15: -0.046, +-0.090, -0.086), so the test sees
#: whether the fit follows the motion rather than the regression.
TRUE_HIP = {"L": np.array([-0.03, 0.075, -0.065]), "R": np.array([-0.03, -0.075, -0.065])}
THIGH = 0.42


def synthetic_legs(F: int = 600, noise: float = 0.0005, seed: int = 0):
    """Pelvis and legs whose thighs turn about known hip centres (ball joints) and whose shanks
    turn about known knee axes (hinges); metres, Z-up.  Returns labels, (F, M, 3), truth."""
    rng = np.random.default_rng(seed)
    t = np.arange(F) / 100.0
    Rp = _rot("z", 20 * np.sin(0.7 * t)) @ _rot("x", 5 * np.sin(1.1 * t))
    op = np.stack([0.3 * t, 0.1 * np.sin(t), 0.95 + 0.02 * np.sin(3 * t)], 1)
    pel = {"LASI": [0, 0.125, 0], "RASI": [0, -0.125, 0], "LPSI": [-0.15, 0.05, 0.0], "RPSI": [-0.15, -0.05, 0.0]}
    m = {k: np.einsum("fij,j->fi", Rp, v) + op for k, v in pel.items()}
    truth = {}
    for s, y, ph in (("L", 1.0, 0.0), ("R", -1.0, 1.3)):
        side = "left" if s == "L" else "right"
        Rt = Rp @ _rot("z", 15 * np.sin(0.9 * t + ph)) @ _rot("y", -40 * np.sin(1.7 * t + ph)) @ _rot("x", y * 20 * np.sin(1.3 * t + ph))
        hip = np.einsum("fij,j->fi", Rp, TRUE_HIP[s]) + op
        thigh = {"THI": [0.03, 0.06 * y, -0.22], "KNE": [0, 0.05 * y, -THIGH], "KNEM": [0, -0.05 * y, -THIGH]}
        for k, v in thigh.items():
            m[f"{s}{k}"] = np.einsum("fij,j->fi", Rt, v) + hip
        knee = np.einsum("fij,j->fi", Rt, [0, 0, -THIGH]) + hip
        Rs = Rt @ _rot("y", 45 * (1 - np.cos(2.1 * t + ph)))
        for k, v in {"TIB": [0.04, 0.045 * y, -0.2], "ANK": [0, 0.035 * y, -0.41], "ANKM": [0, -0.035 * y, -0.41]}.items():
            m[f"{s}{k}"] = np.einsum("fij,j->fi", Rs, v) + knee
        truth[f"{side}_hip"], truth[f"{side}_knee"] = hip, knee
    labels = list(m)
    P = np.stack([m[k] for k in labels], 1) + rng.normal(0, noise, (F, len(labels), 3))
    return labels, P, truth


def _rec(labels, P, fps=100.0) -> MarkerRecording:
    return MarkerRecording(labels=tuple(labels), positions=P, fps=fps, source=Path("synthetic.trc"))


def test_sphere_fit_and_score_recover_a_known_centre():
    rng = np.random.default_rng(1)
    c = np.array([0.1, -0.2, 0.3])
    R = _rot("z", rng.uniform(-60, 60, 300)) @ _rot("y", rng.uniform(-60, 60, 300))
    V = [np.einsum("fij,j->fi", R, d) + c + rng.normal(0, 5e-4, (300, 3)) for d in ([0, 0, -0.3], [0.05, 0.02, -0.2])]
    got, res, rank = sphere_fit(V, prior=np.zeros(3))
    assert np.linalg.norm(got - c) < 2e-3 and rank == 3 and res < 2e-3
    # SCoRE: parent fixed at identity, child frame turning about c (child-local centre cc)
    cc = np.array([0.0, 0.0, 0.25])
    tc = c - np.einsum("fij,j->fi", R, cc)
    I = np.tile(np.eye(3), (300, 1, 1))
    cp_, cc_, res, rank = score_fit(I, np.zeros((300, 3)), R, tc, np.zeros(3), np.zeros(3))
    assert np.allclose(cp_, c, atol=1e-9) and np.allclose(cc_, cc, atol=1e-9) and rank == 6


def test_functional_hip_and_knee_centres_from_synthetic_motion():
    labels, P, truth = synthetic_legs()
    cal = functional_joint_centres(_rec(labels, P), detect_marker_set(labels))
    for joint in ("left_hip", "right_hip", "left_knee", "right_knee"):
        assert cal.method[joint].startswith("functional"), cal.method[joint]
        err = np.linalg.norm(cal.positions[joint] - truth[joint], axis=1)
        assert np.mean(err) < 3e-3, (joint, np.mean(err))
    assert "SCoRE" in cal.method["left_knee"] and "axis depth from regression" in cal.method["left_knee"]
    assert abs(cal.lengths[("left_hip", "left_knee")] - THIGH) < 3e-3


def test_a_still_joint_keeps_the_regression_and_says_why():
    labels, P, _ = synthetic_legs(F=200)
    P = np.repeat(P[:1], 200, axis=0)  # nothing moves
    from physmocap.markers.functional import warn_fallbacks

    cal = functional_joint_centres(_rec(labels, P), detect_marker_set(labels))
    assert cal.method["left_hip"].startswith("regression (Harrington")
    with pytest.warns(UserWarning, match="left_hip \\(the parent and child are seen together in only 1 distinct poses"):
        warn_fallbacks(cal, "synthetic.trc")


def test_too_few_markers_on_a_segment_falls_back_with_a_warning():
    labels, P, _ = synthetic_legs()
    keep = [k for k, lab in enumerate(labels) if lab not in ("LTHI", "LKNEM")]
    labels = [labels[k] for k in keep]
    from physmocap.markers.functional import warn_fallbacks

    cal = functional_joint_centres(_rec(labels, P[:, keep]), detect_marker_set(labels))
    assert "too few markers on left_thigh" in cal.method["left_knee"]
    with pytest.warns(UserWarning, match="left_knee \\(too few markers on left_thigh"):
        warn_fallbacks(cal, "synthetic.trc")
    assert cal.method["right_knee"].startswith("functional")


def _write_trc(path, labels, P, sep="\t", units="mm"):
    F, M, _ = P.shape
    lines = [f"PathFileType{sep}4{sep}(X/Y/Z){sep}{path.name}",
             sep.join(["DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units"]),
             sep.join(["100", "100", str(F), str(M), units]),
             sep.join(["Frame#", "Time"] + [x for lab in labels for x in (lab, "", "")]),
             sep.join(["", ""] + [f"{a}{k + 1}" for k in range(M) for a in "XYZ"])]
    for t in range(F):
        lines.append(sep.join([str(t + 1), f"{t / 100:.4f}"] + [f"{v:.4f}" for v in P[t].ravel()]))
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("up,units,prefix", [("Z", "mm", ""), ("Y", "m", "Subject:"), ("Y", "mm", "Ana_")])
def test_conventions_do_not_change_the_functional_centres(tmp_path, up, units, prefix):
    labels, P, truth = synthetic_legs(F=400)
    Pf = P[..., [1, 2, 0]] if up == "Y" else P  # Y-up file: (y, z, x)
    scale = 1000.0 if units == "mm" else 1.0
    path = tmp_path / "legs.trc"
    named = [f"{prefix}{lab}" if prefix != "Ana_" else f"Ana:{lab}" for lab in labels]
    _write_trc(path, named, Pf * scale, sep="\t" if units == "mm" else ",", units=units)
    rec = read_trc_markers(path)
    cal = functional_joint_centres(rec, detect_marker_set(rec.labels))
    got = cal.positions["left_hip"]
    got = got[:, [2, 0, 1]] if up == "Y" else got  # back to (x, y, z)
    assert np.mean(np.linalg.norm(got - truth["left_hip"], axis=1)) < 3e-3
    assert abs(cal.lengths[("left_hip", "left_knee")] - THIGH) < 3e-3


def test_all_invalid_markers_are_one_clear_error(tmp_path, capsys):
    from physmocap.markers.solve import solve_markers

    labels, P, _ = synthetic_legs(F=20)
    with pytest.raises(InputError, match="every marker sample is invalid"):
        solve_markers(_rec(labels, np.full_like(P, np.nan)))
    path = tmp_path / "empty.trc"
    _write_trc(path, labels, np.zeros_like(P))
    assert main(["solve", str(path), "-o", str(tmp_path / "x.bvh")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "empty.trc" in err[0] and "every marker sample is missing" in err[0]
    assert not (tmp_path / "x.bvh").exists()


def test_solve_rejects_a_non_marker_file(tmp_path, capsys):
    bvh = tmp_path / "a.bvh"
    bvh.write_text("HIERARCHY\n")
    assert main(["solve", str(bvh), "-o", str(tmp_path / "out.bvh")]) == 2
    assert "a.bvh: not a marker file (expected .c3d, .trc, .mcap)" in capsys.readouterr().err


#: Measured on the first 360 frames (solve_markers, 2 iterations per frame): overall marker
#: residual RMS 6-7 mm; solved joint centres 6-8 cm mean from the vendor's joints (whose own
#: placement differs: see docs/markers.md), knee flexion within 3-4 degrees.
def test_cmu_take_solved_end_to_end(tmp_path, capsys):
    c3d = _shared("cmu_01_01_markers.c3d")
    out, rep = tmp_path / "actor.bvh", tmp_path / "res.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["solve", str(c3d), "-o", str(out), "--report", str(rep), "--end", "360"]) == 0
    out_text = capsys.readouterr().out  # the result table on stdout, as retarget's report
    assert "marker residuals" in out_text and "ignored (no segment explains them): RBAC-1" in out_text
    assert "frames/s CPU" in out_text  # the run's speed is printed, not kept in the report file
    again = tmp_path / "again.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["solve", str(c3d), "-o", str(tmp_path / "again.bvh"), "--report", str(again), "--end", "360",
                     "--quiet"]) == 0
    assert again.read_bytes() == rep.read_bytes()  # deterministic: no timings in the file
    report = json.loads(rep.read_text())
    assert report["frames"] == 360
    assert report["overall"]["rms_mm"] < 12.0
    assert all(e["rms_mm"] < 25.0 for e in report["segments"].values() if e["rms_mm"] is not None)
    assert report["markers"]["RBAC-1"]["segment"] is None and report["markers"]["LUPA"]["segment"] == "left_upper_arm"
    # the jumps flex the hips in one plane: a hip centre needs two (Piazza 2004), the regression stays
    assert "the motion stays in one plane" in report["joint_centres"]["left_hip"]
    assert report["joint_centres"]["left_knee"].startswith("functional") and "axis depth" in report["joint_centres"]["left_knee"]
    from physmocap.ik.retarget import map_motion
    from physmocap.sources import load_motion

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        actor = load_motion(out)
        vendor = load_motion(_shared("cmu_01_01_jumps.bvh"))
    assert actor.num_frames == 360 and "left_knee" in actor.skeleton.names
    import sys

    sys.path.insert(0, str(Path(__file__).parents[1] / "scripts"))
    from markers_vs_vendor import JOINTS, compare

    ai, vi = map_motion(actor), map_motion(vendor)
    A = actor.world_positions()[:, [ai[j] for j in JOINTS]]
    B = vendor.world_positions()[:, [vi[j] for j in JOINTS]]
    c = compare(A, B)
    assert c["all"] < 0.09
    assert c["angles"]["left_knee"] < 6.0 and c["angles"]["right_knee"] < 6.0


def test_a_marker_rigid_on_several_segments_is_not_attached():
    """Before: on a take where the trunk hardly moves against the pelvis (vicon_upperbody.trc),
    the box's markers and the arm's were attached to the pelvis, rigid on it within 2 cm.  A
    marker is attached by rigidity only to the one segment it is rigid on."""
    from pathlib import Path

    from scipy.spatial.transform import Rotation

    from physmocap.markers.functional import SegmentFrames, attach_by_rigidity
    from physmocap.markers.recording import MarkerRecording

    F = 100
    t = np.linspace(0.0, 1.0, F)

    def frames(angle: np.ndarray) -> SegmentFrames:
        R = Rotation.from_euler("z", angle[:, None]).as_matrix()
        return SegmentFrames(R, np.zeros((F, 3)), np.ones(F, bool), np.zeros((1, 3)), ("o",), np.zeros(F))

    still = frames(np.zeros(F))
    turning = frames(1.2 * t)  # a second segment turning 70 degrees about the first's origin
    on_turning = turning.to_world(np.array([0.3, 0.0, 0.0]))
    fixed = np.broadcast_to([0.0, 0.4, 0.0], (F, 3))
    rec = MarkerRecording(("A", "B"), np.stack([on_turning, fixed], axis=1), 100.0, Path("synthetic.c3d"))
    assert attach_by_rigidity(rec, {"pelvis": still, "thorax": turning}, {}) == {0: "thorax", 1: "pelvis"}
    # nothing moves: every marker is rigid on both segments, none can be attached
    rec = MarkerRecording(("A", "B"), np.stack([fixed, fixed], axis=1), 100.0, Path("synthetic.c3d"))
    assert attach_by_rigidity(rec, {"pelvis": still, "thorax": frames(np.zeros(F))}, {}) == {}


def test_a_hip_flexing_in_one_plane_keeps_the_regression():
    """A ball joint's centre needs motion in two planes (Piazza 2004): thighs that only flex
    (jumping, walking) leave the hip to the regression, with the reason; a hinge's centre
    along its axis always comes from the regression (rank at most 2 of 3)."""
    labels, P, _ = synthetic_legs(F=400)
    F = P.shape[0]
    t = np.arange(F) / 100.0
    # a still pelvis, and the left thigh's markers turning about the true hip in flexion only
    idx = {lab: k for k, lab in enumerate(labels)}
    hip = TRUE_HIP["L"]
    R = _rot("y", -40 * np.sin(1.7 * t))
    for k, v in {"LTHI": [0.03, 0.06, -0.22], "LKNE": [0, 0.05, -THIGH], "LKNEM": [0, -0.05, -THIGH]}.items():
        P[:, idx[k]] = np.einsum("fij,j->fi", R, v) + hip
    pel = {"LASI": [0, 0.125, 0], "RASI": [0, -0.125, 0], "LPSI": [-0.15, 0.05, 0.0], "RPSI": [-0.15, -0.05, 0.0]}
    for k, v in pel.items():
        P[:, idx[k]] = v
    cal = functional_joint_centres(_rec(labels, P), detect_marker_set(labels))
    assert "the motion stays in one plane" in cal.method["left_hip"], cal.method["left_hip"]
    assert cal.method["right_hip"].startswith("regression")  # its pelvis was frozen too: not a test of it
    V = [np.einsum("fij,j->fi", R, v) + hip for v in ([0, 0.05, -THIGH], [0.03, 0.06, -0.22])]
    got, _, rank = sphere_fit(V, prior=hip + [0.0, 0.04, 0.0], max_rank=2)
    assert rank == 2 and abs(got[1] - (hip[1] + 0.04)) < 1e-9 and np.linalg.norm(got[[0, 2]] - hip[[0, 2]]) < 1e-6


def test_a_narrow_parent_frame_leaves_the_joint_to_the_regression():
    """Two markers and a joint centre nearly in a row (the CMU thigh: hip, LTHI, LKNE) do not fix
    the segment's turn about its long axis: the child's fit would follow skin motion."""
    labels, P, _ = synthetic_legs(F=400)
    idx = {lab: k for k, lab in enumerate(labels)}
    keep = [k for k, lab in enumerate(labels) if lab != "LKNEM"]
    # LTHI moved onto the hip-knee line (5 mm off it): the left thigh's points lie in a row
    P[:, idx["LTHI"]] = 0.5 * (P[:, idx["LKNE"]] + (P[:, idx["LASI"]] + P[:, idx["LPSI"]]) / 2) + 0.005
    labels = [labels[k] for k in keep]
    cal = functional_joint_centres(_rec(labels, P[:, keep]), detect_marker_set(labels))
    assert "the left_thigh frame is too narrow" in cal.method["left_knee"], cal.method["left_knee"]
    assert cal.method["right_knee"].startswith("functional")


def test_a_hinge_axis_far_from_the_medio_lateral_line_is_not_believed():
    """A knee whose shank markers turn about an axis 50 degrees off the line between the knee
    markers (skin motion, not a knee) keeps the regression, with the reason."""
    from physmocap.markers.functional import _axis_deviation

    F = 200
    ang = np.radians(np.linspace(0, 90, F))
    axis = np.array([np.sin(np.radians(50)), np.cos(np.radians(50)), 0.0])  # 50 deg from y (medio-lateral)
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec(ang[:, None] * axis).as_matrix()
    V = [np.einsum("fij,j->fi", R, [0.0, 0.0, -0.3])]
    parent = SegmentFramesStub()
    dev = _axis_deviation(parent, V, np.tile([0.0, 0.05, 0.0], (F, 1)), np.zeros((F, 3)))
    assert abs(dev - 50.0) < 1.0
    assert _axis_deviation(parent, [np.einsum("fij,j->fi", Rotation.from_rotvec(ang[:, None] * [0, 1.0, 0]).as_matrix(),
                                              [0.0, 0.0, -0.3])], np.tile([0.0, 0.05, 0.0], (F, 1)), np.zeros((F, 3))) < 1.0


class SegmentFramesStub:
    """The identity frame, for :func:`_axis_deviation`."""

    def to_local(self, X):
        return X
