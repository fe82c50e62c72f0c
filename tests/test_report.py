"""The quality report: build, table, JSON, plots and ``physmocap report``."""

from __future__ import annotations

import json
import math
import sys

import numpy as np
import pytest

from physmocap.cli import main
from physmocap.errors import OptionError, OutputError
from physmocap.export.trajectory import write_trajectory_npz
from physmocap.ik.contacts import detect_contacts
from physmocap.report import (
    REPORT_FORMAT,
    build_report,
    format_report,
    load_trajectory,
    report_json,
    write_report_json,
)
from physmocap.sources.profiles import map_skeleton
from physmocap.trajectory import Trajectory

from conftest import RETARGET_DIAGNOSTICS, retargeted

pytestmark = RETARGET_DIAGNOSTICS

WALK = "cmu_12_01_walk.bvh"
FIXTURE = __import__("pathlib").Path(__file__).parent / "fixtures" / "contacts" / "cmu_12_01_walk_stance.csv"


def _walk():
    motion, traj = retargeted(WALK, start=0)  # keep CMU's reference frame 0: compare with the whole clip
    return motion, traj


def _contacts(motion):
    return detect_contacts(motion, dict(map_skeleton(motion.skeleton).indices))


def _short(frames: int = 90, character: str = "humanoid"):
    """A short slice of the retargeted walk: (motion, traj, contacts)."""
    motion, traj = retargeted(WALK, character, start=0, end=frames)
    return motion.slice_frames(0, frames), traj, _contacts(motion.slice_frames(0, frames))


def _finite_or_none(x):
    if isinstance(x, dict):
        return all(_finite_or_none(v) for v in x.values())
    if isinstance(x, list):
        return all(_finite_or_none(v) for v in x)
    if isinstance(x, float):
        return math.isfinite(x)
    return True


def test_report_on_the_walk_compares_source_and_result():
    motion, traj = _walk()
    report = build_report(traj, motion, _contacts(motion))
    assert report["format"] == REPORT_FORMAT
    src, res = report["metrics"]["source"], report["metrics"]["result"]
    assert 12 < src["skating"]["mean_cm_s"] < 25  # the raw walk slides
    for group in ("skating", "penetration", "hovering"):
        assert set(src[group]) == set(res[group])
    for key in ("joint_limits", "velocity", "smoothness", "tracking"):
        assert key in res and key not in src
    assert report["source"]["frames"] == traj.num_frames
    assert 0.004 < math.hypot(*report["source"]["floor_slope"]) < 0.015
    assert set(report["contacts"]["labels"]) == {"left_heel", "left_toe", "right_heel", "right_toe"}
    text = format_report(report)
    for needle in ("Foot skating in stance: mean", "Hovering in contact: median", "source", "result", "left_ankle"):
        assert needle in text
    data = json.loads(report_json(report))
    assert _finite_or_none(data)


def test_report_for_the_robot_has_two_sites_per_foot():
    motion, traj, contacts = _short(60, "robot")
    report = build_report(traj, motion, contacts)
    res = report["metrics"]["result"]
    assert res["skating"]["stance_samples"] <= 4 * 60
    assert res["hovering"]["contact_samples"] > 0


def test_json_is_deterministic_sorted_and_has_no_nan(tmp_path):
    motion, traj, contacts = _short()
    report = build_report(traj, motion, contacts)
    report["metrics"]["result"]["extra"] = {"nan": float("nan"), "inf": np.inf, "arr": np.arange(2.0)}
    a = write_report_json(report, tmp_path / "a.json").read_bytes()
    b = write_report_json(report, tmp_path / "b.json").read_bytes()
    assert a == b
    data = json.loads(a)
    assert data["metrics"]["result"]["extra"] == {"arr": [0.0, 1.0], "inf": None, "nan": None}
    assert list(data) == sorted(data)
    assert b"NaN" not in a and b"Infinity" not in a
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.json"]  # no temp files left


def test_json_into_a_missing_directory_is_a_clear_error(tmp_path):
    with pytest.raises(OutputError, match="does not exist"):
        write_report_json({"format": REPORT_FORMAT}, tmp_path / "nope" / "r.json")


def test_frames_must_match():
    motion, traj, contacts = _short()
    with pytest.raises(OptionError, match="the source has 89 frames but the trajectory 90"):
        build_report(traj, motion.slice_frames(0, 89), contacts)
    with pytest.raises(OptionError, match="cover 89 frames"):
        build_report(traj, None, contacts.slice_frames(0, 89))


def test_report_without_source_has_no_source_column():
    motion, traj, contacts = _short()
    report = build_report(Trajectory(traj.character, traj.qpos, traj.fps), None, None)
    assert report["metrics"]["source"] is None and report["source"] is None
    assert "hovering" not in report["metrics"]["result"]
    assert "no source" in format_report(report)


# ---------------------------------------------------------------------------
# Plots
# ---------------------------------------------------------------------------


def test_missing_matplotlib_names_the_extra(monkeypatch):
    from physmocap.plots import require_matplotlib

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(OptionError, match=r"pip install 'physmocap\[plot\]'"):
        require_matplotlib()


# ---------------------------------------------------------------------------
# physmocap report
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def walk_npz(tmp_path_factory):
    motion, traj = retargeted(WALK, start=0)
    return write_trajectory_npz(traj, tmp_path_factory.mktemp("traj") / "walk.npz")


def test_cli_report_prints_table_and_writes_json(walk_npz, tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["report", str(walk_npz), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Foot skating in stance: mean" in text and "tracking error per joint" in text
    data = json.loads(out.read_text())
    assert data["source"]["path"].endswith(WALK)
    assert data["contacts"]["origin"] == "detected"
    res = data["metrics"]["result"]
    assert res["frames"] == 524 and res["tracking"]["all_mean_cm"] < 20
    # the same command gives the same bytes
    again = tmp_path / "r2.json"
    assert main(["report", str(walk_npz), "--json", str(again)]) == 0
    assert again.read_bytes() == out.read_bytes()


def test_cli_report_with_user_contacts_and_plots(walk_npz, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    out = tmp_path / "r.json"
    plots = tmp_path / "plots"
    code = main(["report", str(walk_npz), "--contacts", str(FIXTURE), "--json", str(out), "--plots", str(plots)])
    assert code == 0
    data = json.loads(out.read_text())
    assert data["contacts"]["origin"] == str(FIXTURE)
    assert data["contacts"]["labels"]["left_heel"]["segments"] == 4
    # user labels carry no floor: the source's is still estimated for its figures
    assert data["source"]["floor_m"] is not None
    assert 0 < data["metrics"]["source"]["hovering"]["median_mm"] < 50
    from physmocap.plots import PLOT_FILES

    assert sorted(p.name for p in plots.iterdir()) == sorted(PLOT_FILES)
    for name in PLOT_FILES:
        png = (plots / name).read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000


def test_cli_plots_without_matplotlib_fail_before_writing(walk_npz, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    out = tmp_path / "r.json"
    assert main(["report", str(walk_npz), "--json", str(out), "--plots", str(tmp_path / "p")]) == 2
    assert "pip install 'physmocap[plot]'" in capsys.readouterr().err
    assert not out.exists()


def test_cli_report_without_source(walk_npz, capsys):
    assert main(["report", str(walk_npz), "--no-source"]) == 0
    assert "no source" in capsys.readouterr().out


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d: (d / "x.npz").write_bytes(b"not a zip") and d / "x.npz", "not a trajectory .npz file"),
        (lambda d: d / "missing.npz", "trajectory file not found"),
    ],
)
def test_cli_report_bad_input_is_one_line(tmp_path, capsys, make, message):
    path = make(tmp_path)
    assert main(["report", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("physmocap: error:") and message in err[0]


def test_cli_report_wrong_source_and_columns(walk_npz, tmp_path, capsys):
    from conftest import shared_file

    short = tmp_path / "short.npz"
    with np.load(walk_npz, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    from physmocap.export.trajectory import write_npz

    write_npz(short, arrays)
    assert main(["report", str(short), "--start", "500"]) == 2
    assert "has only 24 (from --start 500)" in capsys.readouterr().err
    arrays["qpos"] = arrays["qpos"][:, :10]
    write_npz(short, arrays)
    assert main(["report", str(short), "--source", str(shared_file(WALK))]) == 2
    assert "has 10 columns" in capsys.readouterr().err


def test_load_trajectory_round_trip(walk_npz):
    motion, traj = _walk()
    back = load_trajectory(walk_npz)
    np.testing.assert_array_equal(back.qpos, traj.qpos)
    assert back.fps == traj.fps and back.character.name == traj.character.name


def test_cli_report_aligns_a_cut_and_resampled_retarget(tmp_path, capsys):
    from physmocap import metrics

    motion, traj = retargeted(WALK, "humanoid", start=100, end=400, fps=30.0)
    npz = write_trajectory_npz(traj, tmp_path / "cut.npz")
    out = tmp_path / "r.json"
    assert main(["report", str(npz), "--start", "100", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    # tracking is measured against the targets the retargeter stored in the file
    expected = metrics.tracking_errors(traj)["all_mean_cm"]
    assert data["metrics"]["result"]["tracking"]["all_mean_cm"] == pytest.approx(expected, rel=1e-4)
    # and the source the command re-reads lines up with the frames retarget used
    cut = motion.slice_frames(100, 400).resample(30.0)
    idx = dict(map_skeleton(cut.skeleton).indices)
    src = metrics.source_skating(cut, idx)
    assert data["metrics"]["source"]["skating"]["mean_cm_s"] == pytest.approx(src["mean_cm_s"], rel=1e-4)
    assert data["source"]["frames"] == traj.num_frames and data["source"]["fps"] == 30.0


def _without_member(src, dst, member: str) -> None:
    """Copy the NPZ ``src`` to ``dst`` without ``member`` (a file of an older physmocap)."""
    import zipfile

    with zipfile.ZipFile(src) as zi, zipfile.ZipFile(dst, "w") as zo:
        for info in zi.infolist():
            if info.filename != member:
                zo.writestr(info, zi.read(info))


def test_report_on_the_npz_agrees_with_retarget_report(tmp_path, capsys):
    """`report walk.npz` measures the fidelity figures `retarget --report` gave (the actor's
    speeds scaled by the root scale the retarget used, stored in the NPZ as target_scale); a
    file without it has the scale recomputed as a default retarget does, with a warning."""
    npz, first, again = tmp_path / "walk.npz", tmp_path / "walk_report.json", tmp_path / "r.json"
    assert main(["retarget", "example", "-o", str(tmp_path / "walk.bvh"), "--qpos", str(npz), "--report",
                 str(first), "--end", "200", "--quiet"]) == 0
    assert main(["report", str(npz), "--json", str(again)]) == 0
    fid = json.loads(first.read_text())["fidelity"]
    assert fid and json.loads(again.read_text())["fidelity"] == fid
    k = float(np.load(npz)["target_scale"])
    assert 0.5 < k < 2 and k != 1.0
    old = tmp_path / "old.npz"
    _without_member(npz, old, "target_scale.npy")
    from physmocap.errors import PhysmocapWarning

    with pytest.warns(PhysmocapWarning, match="old.npz: the file stores no root scale"):
        assert main(["report", str(old), "--json", str(again)]) == 0
    assert json.loads(again.read_text())["fidelity"] == fid


@pytest.mark.parametrize("value", [np.float64(0.0), np.float64(np.nan), np.array(["x"])])
def test_bad_stored_root_scale_is_one_line(tmp_path, capsys, value):
    npz = tmp_path / "walk.npz"
    assert main(["retarget", "example", "-o", str(npz), "--end", "20", "--quiet"]) == 0
    data = dict(np.load(npz))
    data["target_scale"] = value
    np.savez(npz, **data)
    assert main(["report", str(npz)]) == 2
    err = capsys.readouterr().err
    assert "physmocap: error:" in err and "walk.npz: 'target_scale'" in err


def test_report_reloads_the_character_with_the_retargets_mapping_file(tmp_path, recwarn):
    """A trajectory NPZ records the mapping file the retarget was given (``map_path``, relative
    to the NPZ, deterministic bytes); ``report`` reloads the character with it, not with the
    mapping found beside the model, and warns once, naming it, when it is gone."""
    import shutil

    from physmocap.resources import mjcf_dir

    for d in ("chars", "maps", "out"):
        (tmp_path / d).mkdir()
    shutil.copy(mjcf_dir() / "robot.xml", tmp_path / "chars" / "robot.xml")
    text = (mjcf_dir() / "robot.map.toml").read_text()
    (tmp_path / "maps" / "mine.map.toml").write_text(text.replace('name = "robot"', 'name = "mine"'))
    (tmp_path / "chars" / "robot.map.toml").write_text(text)  # what the model finds by itself
    out = tmp_path / "out" / "w.npz"
    argv = ["retarget", "example", "-o", str(out), "--character", str(tmp_path / "chars" / "robot.xml"),
            "--map", str(tmp_path / "maps" / "mine.map.toml"), "--end", "20", "--quiet"]
    assert main(argv) == 0
    first = out.read_bytes()
    assert main(argv) == 0 and out.read_bytes() == first  # the same bytes on a re-run
    with np.load(out, allow_pickle=False) as z:
        assert str(z["map_path"]) == "../maps/mine.map.toml" and str(z["mjcf_path"]) == "../chars/robot.xml"
    report = tmp_path / "r.json"
    recwarn.clear()
    assert main(["report", str(out), "--json", str(report)]) == 0
    assert not [w for w in recwarn if "mapping" in str(w.message)]
    assert json.loads(report.read_text())["character"]["name"] == "mine"
    # the same model named with --character keeps the recorded mapping; --map overrides it
    assert main(["report", str(out), "--character", str(tmp_path / "chars" / "robot.xml"), "--json", str(report)]) == 0
    assert json.loads(report.read_text())["character"]["name"] == "mine"
    assert main(["report", str(out), "--map", str(tmp_path / "chars" / "robot.map.toml"), "--json", str(report)]) == 0
    assert json.loads(report.read_text())["character"]["name"] == "robot"
    (tmp_path / "maps" / "mine.map.toml").unlink()
    with pytest.warns(Warning) as caught:
        assert main(["report", str(out), "--json", str(report)]) == 0
    warned = [str(w.message) for w in caught]
    assert len(warned) == 1 and f"mapping file {tmp_path / 'maps' / 'mine.map.toml'} recorded" in warned[0], warned
    assert f"using the mapping file {tmp_path / 'chars' / 'robot.map.toml'} instead" in warned[0]
    assert json.loads(report.read_text())["character"]["name"] == "robot"


def test_a_trajectory_of_the_bundled_mapping_records_none(tmp_path, capsys):
    """The default humanoid's bundled mapping is not recorded (no path into the installation);
    a file without ``map_path`` (an older physmocap's) loads as before."""
    out = tmp_path / "w.npz"
    assert main(["retarget", "example", "-o", str(out), "--end", "12", "--quiet"]) == 0
    with np.load(out, allow_pickle=False) as z:
        assert str(z["map_path"]) == ""
        arrays = {k: z[k] for k in z.files if k != "map_path"}
    old = tmp_path / "old.npz"
    np.savez(old, **arrays)
    capsys.readouterr()
    assert load_trajectory(old).character.name == "humanoid"
    assert capsys.readouterr().err == ""


def test_the_report_gives_the_pelvis_drift_of_a_retarget_with_its_targets(tmp_path):
    """The fidelity section carries the pelvis's drift from its target (no fit, docs/metrics.md):
    under a centimetre offline; absent (None) for a trajectory read back without its targets."""
    out = tmp_path / "walk.json"
    assert main(["retarget", "example", "-o", str(tmp_path / "walk.bvh"), "--report", str(out), "--quiet"]) == 0
    drift = json.loads(out.read_text())["fidelity"]["pelvis_drift"]
    assert drift["mean_cm"] is not None and drift["mean_cm"] < 1.0 and drift["max_cm"] >= drift["mean_cm"]
    report = json.loads(out.read_text())
    assert "pelvis drift from its target" in format_report(report)
