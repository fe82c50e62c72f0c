"""`physmocap preview` (issue 10): headless renders of the character beside its source skeleton."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

from physmocap.cli import main

imageio = pytest.importorskip("imageio.v2", reason="imageio is not installed: pip install 'physmocap[render]'")


@pytest.fixture(scope="module")
def backend():
    from physmocap.render.backend import RenderError, ensure_backend

    try:
        return ensure_backend()
    except RenderError as exc:
        pytest.skip(f"no OpenGL backend on this machine: {exc}")


def _run(argv: list[str]) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return main(argv)


def _coloured(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the left (blue) and right (red) side colours."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (b > 120) & (b > r + 50), (r > 120) & (r > b + 50)


def test_contact_sheet_shows_character_above_source(backend, tmp_path):
    out = tmp_path / "walk.png"
    assert _run(["preview", "example", "-o", str(out), "--end", "90", "--count", "3", "--size", "200x200", "--quiet"]) == 0
    sheet = imageio.imread(out)
    assert sheet.shape[:2] == (2 * 200, 3 * 200)
    panels = [[sheet[r * 200:(r + 1) * 200, c * 200:(c + 1) * 200, :3] for c in range(3)] for r in range(2)]
    for row in panels:
        for img in row:
            left, right = _coloured(img)
            assert left.sum() > 15 and right.sum() > 15  # both sides drawn, in their colours
    # the character's pixels move between frames (a walk), and so do the skeleton's
    for row in panels:
        a, b = (_coloured(row[0])[0] | _coloured(row[0])[1]), (_coloured(row[2])[0] | _coloured(row[2])[1])
        assert (a ^ b).sum() > 20


def test_video_and_gif_have_every_frame(backend, tmp_path):
    mp4, gif = tmp_path / "walk.mp4", tmp_path / "walk.gif"
    argv = ["example", "--end", "25", "--size", "96x80", "--quiet", "--camera", "front"]
    assert _run(["preview", argv[0], "-o", str(mp4), *argv[1:]]) == 0
    assert _run(["preview", argv[0], "-o", str(gif), *argv[1:], "--layout", "overlay"]) == 0
    # 24 frames at 120 Hz (0.19 s) play at 30 frames per second by default: 6 frames
    reader = imageio.get_reader(mp4)
    assert reader.count_frames() == 6 and reader.get_meta_data()["size"] == (96, 80)
    assert reader.get_meta_data()["fps"] == 30
    frames = imageio.mimread(gif)
    assert len(frames) == 6 and frames[0].shape[:2] == (80, 96)
    assert not list(tmp_path.glob(".*tmp*"))  # no temporary files left


def test_retarget_writes_a_preview_too(backend, tmp_path):
    out, sheet = tmp_path / "walk.npz", tmp_path / "sheet.png"
    assert _run(["retarget", "example", "-o", str(out), "--end", "30", "--preview", str(sheet), "--quiet"]) == 0
    assert out.exists() and sheet.exists()
    # and a saved trajectory previews with its source
    again = tmp_path / "again.png"
    assert _run(["preview", str(out), "--source", "example", "-o", str(again), "--count", "2", "--size", "64x64"]) == 0
    assert imageio.imread(again).shape[:2] == (128, 128)


def test_a_saved_trajectory_previews_from_the_source_frame_it_records(backend, tmp_path):
    """Before: the source was cut where a fresh retarget would start (frame 1 of the bundled
    walk, with a warning telling the user to pass --start 0), not where the saved one did."""
    out = tmp_path / "walk.npz"
    assert _run(["retarget", "example", "-o", str(out), "--start", "5", "--end", "30", "--quiet"]) == 0
    sheet = tmp_path / "sheet.png"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no reference-pose warning: the file says where it starts
        assert main(["preview", str(out), "--source", "example", "-o", str(sheet), "--count", "2",
                     "--size", "64x64", "--quiet"]) == 0
    assert imageio.imread(sheet).shape[:2] == (128, 128)


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["preview", "example", "-o", "{tmp}/x.avi"], "cannot write .avi previews; use .gif, .mp4 or .png"),
        (["preview", "example", "-o", "{tmp}/missing/x.mp4"], "does not exist"),
        (["preview", "example", "-o", "{tmp}/x.png", "--size", "10x10000"], "--size"),
        (["preview", "example", "-o", "{tmp}/x.png", "--camera", "diagonal"], "--camera"),
        (["preview", "example", "-o", "{tmp}/x.png", "--frames", "1,a"], "--frames"),
        (["preview", "{tmp}/none.npz", "-o", "{tmp}/x.png"], "not found"),
        (["preview", "example", "-o", "{tmp}/x.png", "--camera", "nan,10"], "azimuth and elevation must be finite"),
        # every frame of the clip in one row: 321 megapixels (3.4 GB while it was assembled)
        (["preview", "example", "-o", "{tmp}/x.png", "--count", "100000", "--quiet"], "megapixels, more than 64"),
    ],
)
def test_bad_input_is_one_clear_line(argv, needle, tmp_path, capsys):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    assert _run(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and needle in err, err
    assert not [p for p in tmp_path.iterdir() if p.suffix in (".png", ".mp4", ".gif", ".avi")]


def test_missing_opengl_backend_says_what_to_install(tmp_path):
    env = dict(os.environ, MUJOCO_GL="osmesa", PYOPENGL_PLATFORM="osmesa")
    env.pop("DISPLAY", None)
    from ctypes.util import find_library

    if find_library("OSMesa"):
        pytest.skip("OSMesa is installed here: cannot show the missing-backend error with it")
    r = subprocess.run(
        [sys.executable, "-m", "physmocap", "preview", "example", "-o", str(tmp_path / "x.png"), "--end", "10", "--quiet"],
        capture_output=True, text=True, env=env, timeout=120,
    )
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if "error" in ln]
    assert len(lines) == 1 and "libosmesa6" in lines[0] and "Traceback" not in r.stderr
    assert not (tmp_path / "x.png").exists()


def test_view_without_a_display_suggests_preview(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert _run(["view", "example"]) == 2
    err = capsys.readouterr().err
    assert "no display" in err and "physmocap preview" in err and "Traceback" not in err


# --- placement, determinism, frame rates, robustness -------------------------------------------


def test_source_skeleton_sits_where_the_retargeter_put_the_actor():
    """The midpoint of the placed source hips is the retargeter's root anchor: the midpoint
    of its hip targets (before planting shifts them), frame by frame."""
    from conftest import retargeted
    from physmocap.render.source import preview_input

    with warnings.catch_warnings():  # velocity caps on a few frames: not what is tested here
        warnings.simplefilter("ignore")
        motion, traj = retargeted("cmu_12_01_walk.bvh", start=1, end=61)
    inp = preview_input(traj)
    joints = traj.joint_indices
    targets = traj.targets
    raw = targets.info.get("raw_positions", targets.positions)
    placed = inp.skeleton.positions[:, [joints["left_hip"], joints["right_hip"]]].mean(axis=1)
    anchor = raw[:, [targets.index("left_hip"), targets.index("right_hip")]].mean(axis=1)
    np.testing.assert_allclose(placed, anchor, atol=1e-9)
    assert inp.first == 1 and inp.contacts is not None


def test_sheet_bytes_are_deterministic(backend, tmp_path):
    outs = [tmp_path / f"s{k}.png" for k in (1, 2)]
    for out in outs:
        assert _run(["preview", "example", "-o", str(out), "--end", "40", "--count", "2", "--size", "64x48", "--quiet"]) == 0
    assert outs[0].read_bytes() == outs[1].read_bytes()


def test_trajectory_frames_are_picked_at_fps(backend, tmp_path):
    npz, mp4 = tmp_path / "walk.npz", tmp_path / "walk.mp4"
    assert _run(["retarget", "example", "-o", str(npz), "--end", "61", "--quiet"]) == 0
    assert _run(["preview", str(npz), "-o", str(mp4), "--fps", "10", "--size", "64x48", "--quiet"]) == 0
    reader = imageio.get_reader(mp4)
    assert reader.count_frames() == 5 and reader.get_meta_data()["fps"] == 10  # 60 frames at 120 Hz: 0.49 s


def test_unusable_outputs_and_characters_are_one_line(tmp_path, capsys):
    # an MP4 of odd size is refused before the retarget (libx264 cannot encode it)
    assert _run(["preview", "example", "-o", str(tmp_path / "x.mp4"), "--size", "65x48"]) == 2
    err = capsys.readouterr().err
    assert "even width and height" in err and len(err.strip().splitlines()) == 1
    # a trajectory whose character file is gone
    npz = tmp_path / "walk.npz"
    assert _run(["retarget", "example", "-o", str(npz), "--end", "11", "--quiet"]) == 0
    with np.load(npz, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["mjcf_path"] = np.array(str(tmp_path / "gone.xml"))
    from physmocap.export.trajectory import write_npz

    write_npz(npz, arrays)
    capsys.readouterr()
    assert _run(["preview", str(npz), "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "gone.xml" in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["walk.npz"]


def test_renders_when_mujoco_was_imported_first(backend, tmp_path):
    """MuJoCo picks its OpenGL backend at its own import: a program that imports mujoco
    before physmocap still renders headless."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL", "PYOPENGL_PLATFORM")}
    code = (
        "import mujoco\n"
        "from physmocap.render.backend import ensure_backend\n"
        "ensure_backend()\n"
        "m = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size=\".1\"/></worldbody></mujoco>')\n"
        "print(mujoco.Renderer(m, 16, 16).render().shape)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0 and "(16, 16, 3)" in r.stdout, r.stderr


@pytest.mark.parametrize("suffix,end", [(".mp4", "200"), (".mp4", "524"), (".gif", "200"), (".png", "524")])
def test_file_size_limit_is_one_line_naming_the_preview(backend, tmp_path, suffix, end):
    """Over ``ulimit -f``: ffmpeg is killed by SIGXFSZ (a short video, all its frames already in
    the pipe, used to pass as written; a long one gave imageio's nine-line 'Broken pipe' dump),
    Pillow's GIF write fails in its close: one line naming the preview, no file left."""
    import resource

    out = tmp_path / f"big{suffix}"

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (50 * 1024, 50 * 1024))

    r = subprocess.run([sys.executable, "-m", "physmocap", "preview", "example", "-o", str(out), "--end", end],
                       capture_output=True, text=True, timeout=600, preexec_fn=limit)
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("physmocap: error:")]
    assert r.returncode == 2 and len(errors) == 1, r.stderr
    assert errors[0].startswith(f"physmocap: error: {out}: not written: File too large"), r.stderr
    assert "Traceback" not in r.stderr and "FFMPEG" not in r.stderr and "Exception ignored" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_mp4_complete_tells_a_cut_video(backend, tmp_path):
    from physmocap.render.output import mp4_complete

    out = tmp_path / "v.mp4"
    assert _run(["preview", "example", "-o", str(out), "--end", "20"]) == 0
    data = out.read_bytes()
    assert mp4_complete(out)
    for cut in (len(data) - 1, len(data) // 2, 4):
        out.write_bytes(data[:cut])
        assert not mp4_complete(out)


def test_an_overlay_sheet_draws_the_source_over_the_character(backend, tmp_path):
    """Before: ``--layout overlay`` was silently ignored for a PNG sheet (two rows, as beside)."""
    out = tmp_path / "walk.png"
    argv = ["preview", "example", "-o", str(out), "--end", "90", "--count", "2", "--size", "200x200", "--quiet"]
    assert _run([*argv, "--layout", "overlay"]) == 0
    sheet = imageio.imread(out)
    assert sheet.shape[:2] == (200, 2 * 200)  # one row: character and source together
    beside = tmp_path / "beside.png"
    assert _run([*argv[:3], str(beside), *argv[4:]]) == 0
    character_only = imageio.imread(beside)[:200]
    assert np.abs(sheet[..., :3].astype(int) - character_only[..., :3].astype(int)).sum() > 0  # the skeleton drawn on it


def test_captions_tell_frames_apart_at_high_rates():
    """Before: two decimals, so frames 674 and 675 of a 120 Hz clip both read 5.62 s."""
    from physmocap.render.output import _caption

    assert _caption(674, 0, 120.0) != _caption(675, 0, 120.0)
    assert _caption(674, 0, 120.0).endswith("t=5.617 s")
    assert _caption(30, 0, 30.0).endswith("t=1.00 s")
