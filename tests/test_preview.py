"""physmocap preview: what is drawn where, the files written, and the errors.

Rendering tests need an OpenGL backend (EGL or OSMesa headless; CI installs
them); they skip with the reason where none exists.  Clips are 90 frames of the
shared CMU walk, images tiny.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import retargeted
from physmocap.cli import main
from physmocap.errors import OptionError
from physmocap.models import load_character
from physmocap.preview.camera import CameraSpec
from physmocap.preview.clip import CENTRE, LEFT, RIGHT, Placement, character_sides, result_clip, tree_sides
from physmocap.preview.gl import BackendError
from physmocap.preview.output import sheet_indices, video_indices, write_preview
from physmocap.preview.render import ClipRenderer, RenderOptions

iio = pytest.importorskip("imageio.v3", reason="physmocap[render] (imageio) is not installed")

WALK = "cmu_12_01_walk.bvh"


@pytest.fixture(scope="module")
def clip():
    motion, traj = retargeted(WALK, start=1, end=91)
    return result_clip(traj, motion)


@pytest.fixture(scope="module")
def renderer(clip):
    try:
        r = ClipRenderer(clip, RenderOptions(width=160, height=120))
    except BackendError as exc:
        pytest.skip(f"no OpenGL backend to render with: {exc}")
    yield r
    r.close()


@pytest.fixture(scope="module")
def trajectory_npz(tmp_path_factory):
    from physmocap.export.trajectory import write_trajectory_npz

    _, traj = retargeted(WALK, start=1, end=91)
    return write_trajectory_npz(traj, tmp_path_factory.mktemp("traj") / "walk.npz")


# --- what goes where (no rendering) ---------------------------------------------------------------


def test_tree_sides_inherit_down_and_up():
    #        0 root
    #   1 (unseeded, all seeded descendants left)   4 right seed   6 spine
    #   2 left seed -> 3 (inherits left)            5 (inherits right)
    parents = np.array([-1, 0, 1, 2, 0, 4, 0])
    sides = tree_sides(parents, {2: LEFT, 4: RIGHT})
    assert list(sides) == [CENTRE, LEFT, LEFT, LEFT, RIGHT, RIGHT, CENTRE]


def test_character_sides_follow_the_mapping():
    character = load_character("humanoid")
    sides = character_sides(character)
    model = character.model
    for canon, tf in character.tracked.items():
        body = model.site_bodyid[model.site(tf.name).id] if tf.kind == "site" else model.body(tf.name).id
        expect = LEFT if canon.startswith("left_") else RIGHT if canon.startswith("right_") else None
        if expect is not None:
            assert sides[body] == expect, canon
    assert sides[model.body(character.tracked["pelvis"].name).id if character.tracked["pelvis"].kind == "body"
                 else model.site_bodyid[model.site(character.tracked["pelvis"].name).id]] == CENTRE


def test_placement_scales_about_the_start_point():
    pl = Placement(scale=0.5, origin_xy=np.array([1.0, 2.0]), source_floor=0.1, ankle_actor=0.1, ankle_character=0.08)
    out = pl.apply(np.array([[1.0, 2.0, 0.2], [3.0, 2.0, 1.2]]))
    np.testing.assert_allclose(out, [[1.0, 2.0, 0.08], [2.0, 2.0, 0.58]])


def test_source_skeleton_sits_where_the_retargeter_put_the_actor(clip):
    """The midpoint of the placed source hips is exactly the retargeter's root anchor: the
    midpoint of its hip targets (before planting shifts them)."""
    _, traj = retargeted(WALK, start=1, end=91)
    targets = traj.targets
    raw = targets.info.get("raw_positions", targets.positions)
    source = traj.stats["joint_indices"]
    placed = clip.skeleton.positions[:, [source["left_hip"], source["right_hip"]]].mean(axis=1)
    anchor = raw[:, [targets.index("left_hip"), targets.index("right_hip")]].mean(axis=1)
    np.testing.assert_allclose(placed, anchor, atol=1e-5)  # float32 skeleton
    assert list(clip.frame_numbers[:3]) == [1, 2, 3]
    sides = set(clip.skeleton.sides.tolist())
    assert sides == {CENTRE, LEFT, RIGHT}


def test_frame_selection(clip):
    idx, fps = video_indices(clip, None)
    assert fps == 30.0 and idx[0] == 0 and len(idx) == 23  # 90 frames at 120 Hz = 0.742 s
    assert list(sheet_indices(clip, count=3)) == [0, 44, 89]
    assert list(sheet_indices(clip, frames=[1, 50])) == [0, 49]
    with pytest.raises(OptionError, match="not in the previewed frames 1 to 90"):
        sheet_indices(clip, frames=[500])


def test_camera_parsing():
    assert CameraSpec.parse("front").angles(90.0) == (270.0, -12.0)
    assert CameraSpec.parse("30,-45").angles(90.0) == (30.0, -45.0)
    for bad in ("diagonal", "1,2,3", "0,-120"):
        with pytest.raises(OptionError):
            CameraSpec.parse(bad)


# --- rendering ---------------------------------------------------------------------------------


def _colour_mask(image: np.ndarray, side: int) -> np.ndarray:
    """Pixels of the side's hue (shading scales the colour, so compare channel ratios)."""
    r, g, b = (image[..., k].astype(float) + 1.0 for k in range(3))
    if side == LEFT:
        return (b > 1.5 * r) & (b > 1.3 * g)
    return (r > 1.8 * g) & (r > 1.8 * b)


def test_frame_shows_character_left_and_skeleton_right(renderer):
    """Side by side: character pixels on the left half, skeleton pixels on the right half,
    both with left (blue) and right (red) sides."""
    empty = renderer.frame(30, character=False, skeleton=False)
    only_char = renderer.frame(30, skeleton=False)
    only_skel = renderer.frame(30, character=False)
    W = empty.shape[1]
    for image, half in ((only_char, slice(0, W // 2)), (only_skel, slice(W // 2, W))):
        drawn = np.any(image != empty, axis=-1)
        drawn[:20] = False  # the caption
        cols = np.flatnonzero(drawn.any(axis=0))
        assert drawn.sum() > 100
        assert half.start <= np.median(cols) < half.stop
        for side in (LEFT, RIGHT):
            assert (_colour_mask(image, side) & drawn).sum() > 5, f"no {side} pixels"


def test_character_moves_between_frames(renderer):
    a = renderer.frame(0, skeleton=False, character=True)
    b = renderer.frame(60, skeleton=False, character=True)
    assert np.mean(np.any(a[20:] != b[20:], axis=-1)) > 0.005


def test_sheet_is_deterministic_and_laid_out(clip, tmp_path):
    try:
        options = RenderOptions(width=48, height=64)
        paths = [write_preview(clip, tmp_path / f"s{k}.png", options, count=5, progress=False) for k in (1, 2)]
    except BackendError as exc:
        pytest.skip(f"no OpenGL backend to render with: {exc}")
    assert paths[0].read_bytes() == paths[1].read_bytes()
    sheet = iio.imread(paths[0])
    # 5 frames in 4 columns: 2 bands of (character row, source row), 2-pixel gaps
    assert sheet.shape == (4 * 64 + 3 * 2, 4 * 48 + 3 * 2, 3)
    assert sheet[:64, :48].std() > 5  # not blank
    assert not np.array_equal(sheet[:64, :48], sheet[66:130, :48])  # character row != source row
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s1.png", "s2.png"]  # no temporaries left


def test_mp4_and_gif_have_the_frames(clip, tmp_path):
    try:
        mp4 = write_preview(clip, tmp_path / "w.mp4", RenderOptions(width=64, height=48), fps=20, progress=False)
    except BackendError as exc:
        pytest.skip(f"no OpenGL backend to render with: {exc}")
    import imageio.v2 as iio2

    with iio2.get_reader(mp4, format="FFMPEG") as reader:
        assert reader.count_frames() == 15  # 0.742 s at 20 fps
        assert reader.get_meta_data()["size"] == (64, 48)
        assert reader.get_data(0).std() > 5  # not blank
    gif = write_preview(clip, tmp_path / "w.gif", RenderOptions(width=64, height=48), fps=10, progress=False)
    assert iio.imread(gif, index=None).shape[:3] == (8, 48, 64)


@pytest.mark.parametrize("name", ["w.mp4", "w.gif", "w.png"])
def test_failed_render_leaves_no_file(clip, tmp_path, monkeypatch, name):
    calls = []

    def broken(self, i, character=True, skeleton=True):
        calls.append(i)
        if len(calls) > 2:
            raise RuntimeError("boom")
        return np.zeros((48, 64, 3), np.uint8)

    def init(self, clip, options=None):
        self.clip, self.options = clip, options

    monkeypatch.setattr(ClipRenderer, "__init__", init)
    monkeypatch.setattr(ClipRenderer, "close", lambda self: None)
    monkeypatch.setattr(ClipRenderer, "frame", broken)
    with pytest.raises(RuntimeError):
        write_preview(clip, tmp_path / name, RenderOptions(width=64, height=48), count=4, progress=False)
    assert list(tmp_path.iterdir()) == []


# --- command line ------------------------------------------------------------------------------


def _one_line_error(capsys, argv, *text):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("physmocap: error:"), err
    for t in text:
        assert t in err[0]


def test_cli_preview_of_a_trajectory(trajectory_npz, tmp_path, capsys):
    out = tmp_path / "sheet.png"
    argv = ["preview", str(trajectory_npz), "-o", str(out), "--frames", "10,40", "--size", "48x64", "--quiet"]
    try:
        status = main(argv)
    except BackendError as exc:  # pragma: no cover - main turns it into exit 2
        pytest.skip(str(exc))
    if status == 2 and "OpenGL" in capsys.readouterr().err:
        pytest.skip("no OpenGL backend to render with")
    assert status == 0 and iio.imread(out).shape == (130, 98, 3)


def test_cli_errors(trajectory_npz, tmp_path, capsys, monkeypatch):
    npz = str(trajectory_npz)
    _one_line_error(capsys, ["preview", npz, "-o", str(tmp_path / "a.avi")], "cannot write a preview as '.avi'")
    _one_line_error(capsys, ["preview", npz, "-o", str(tmp_path / "no" / "a.mp4")], "does not exist")
    _one_line_error(capsys, ["preview", npz, "-o", str(tmp_path / "a.png"), "--size", "big"], "WIDTHxHEIGHT")
    _one_line_error(capsys, ["preview", npz, "-o", str(tmp_path / "a.mp4"), "--size", "65x48"], "even width")
    _one_line_error(capsys, ["preview", npz, "-o", str(tmp_path / "a.png"), "--camera", "up"], "unknown camera view")
    _one_line_error(capsys, ["preview", npz, "-o", str(tmp_path / "a.png"), "--start", "500"], "selects no frame")
    # a trajectory whose character file is gone
    with np.load(trajectory_npz, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["mjcf_path"] = np.array(str(tmp_path / "gone.xml"))
    from physmocap.export.trajectory import write_npz

    lost = write_npz(tmp_path / "lost.npz", arrays)
    _one_line_error(capsys, ["preview", str(lost), "-o", str(tmp_path / "a.png")], "gone.xml", "does not exist")
    # no display: view says so and points at preview
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    _one_line_error(capsys, ["view", npz], "no display", "physmocap preview")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lost.npz"]


def test_missing_opengl_names_the_package(clip, tmp_path, monkeypatch):
    import ctypes.util

    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None)
    with pytest.raises(BackendError, match="apt-get install libegl1, or libosmesa6"):
        write_preview(clip, tmp_path / "a.png", progress=False)
    assert list(tmp_path.iterdir()) == []
