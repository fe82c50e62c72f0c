"""Bad marker input (issue 11 leftovers): repeated labels, clips too short to calibrate, TRC
errors as ``FILE:LINE: message``, the public rigid fit."""

from __future__ import annotations

import numpy as np
import pytest

from physmocap.errors import InputError, PhysmocapWarning
from physmocap.sources.trc import read_trc_markers
from test_markers import _c3d_copy, _standing_markers, _write_trc, solve_fails_cleanly


def test_repeated_trc_labels_are_named_and_told_apart(tmp_path):
    """They were read silently, the first taking the role and the second hidden behind it."""
    labels, P, _ = _standing_markers(6)
    k = labels.index("LKNE")
    twice = list(labels)
    twice[k + 3] = "LKNE"
    path = tmp_path / "twice.trc"
    _write_trc(path, twice, P * 1000)
    with pytest.warns(UserWarning, match=rf"twice\.trc:4: repeated marker label\(s\): LKNE \(markers {k + 1}, {k + 4}\); "
                      r"the first of each keeps the label and its role, the others are renamed LKNE#2"):
        rec = read_trc_markers(path)
    assert rec.labels[k] == "LKNE" and rec.labels[k + 3] == "LKNE#2" and len(set(rec.labels)) == len(rec.labels)


def test_a_repeated_label_can_be_given_its_role_by_a_marker_set(tmp_path):
    from physmocap.markers.markerset import recording_marker_set

    labels, P, _ = _standing_markers(6)
    twice = [lab if lab != "RKNE" else "LKNE" for lab in labels]
    path = tmp_path / "twice.trc"
    _write_trc(path, twice, P * 1000)
    ms_file = tmp_path / "set.toml"
    ms_file.write_text('[markers]\nRKNE = "LKNE#2"\n')
    with pytest.warns(UserWarning, match="repeated marker label"):
        rec = read_trc_markers(path)
    ms = recording_marker_set(rec, ms_file)
    assert rec.labels[ms.roles["RKNE"]] == "LKNE#2" and rec.labels[ms.roles["LKNE"]] == "LKNE"


def test_repeated_c3d_labels_are_named(tmp_path):
    pytest.importorskip("ezc3d")
    from physmocap.sources.c3d import read_c3d_markers

    import ezc3d

    from conftest import shared_file

    labels = list(ezc3d.c3d(str(shared_file("cmu_01_01_markers.c3d")))["parameters"]["POINT"]["LABELS"]["value"])
    labels[7] = labels[2]
    path = tmp_path / "twice.c3d"
    _c3d_copy(path, labels=labels, frames=20)
    with pytest.warns(UserWarning, match=rf"twice\.c3d: POINT:LABELS: repeated marker label\(s\): {labels[2]} \(markers 3, 8\)"):
        rec = read_c3d_markers(path)
    assert rec.labels[7] == f"{labels[2]}#2"


@pytest.mark.parametrize("frames", [1, 2, 9])
def test_a_clip_too_short_to_calibrate_says_so(tmp_path, capsys, frames):
    """A 2-frame solve gave a long joint-centre warning, then 'no marker could be attached'."""
    labels, P, _ = _standing_markers(frames)
    path = tmp_path / "short.trc"
    _write_trc(path, labels, P * 1000)
    solve_fails_cleanly(capsys, path, tmp_path / "a.bvh",
                        f"too short to calibrate ({frames} frame{'s' if frames > 1 else ''}, need 10)")


def test_the_stream_refuses_a_calibration_too_short(tmp_path):
    from physmocap.markers.recording import MarkerRecording
    from physmocap.markers.stream import MarkerStream

    labels, P, _ = _standing_markers(3)
    with pytest.raises(InputError, match=r"cal\.trc: too short to calibrate \(3 frames, need 10\)"):
        MarkerStream.calibrate(MarkerRecording(tuple(labels), P, 100.0, tmp_path / "cal.trc"))


@pytest.mark.parametrize("line,edit,needle", [
    (2, lambda cells: ["fast", "fast"] + cells[2:], r"hdr\.trc:3: DataRate must be a positive number"),
    (2, lambda cells: cells[:4] + ["furlong"], r"hdr\.trc:3: unknown Units 'furlong'"),
    (0, lambda cells: ["Nope"] + cells[1:], r"hdr\.trc:1: not a TRC file"),
    (6, lambda cells: cells[:5] + ["1e12"] + cells[6:], r"hdr\.trc:7: marker \w+ X is out of range"),
])
def test_trc_errors_read_file_colon_line(tmp_path, line, edit, needle):
    labels, P, _ = _standing_markers(4)
    path = tmp_path / "hdr.trc"
    _write_trc(path, labels, P * 1000)
    lines = path.read_text().splitlines()
    lines[line] = "\t".join(edit(lines[line].split("\t")))
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=needle):
        read_trc_markers(path)


def test_the_rigid_fit_is_public_and_recovers_a_pose():
    from scipy.spatial.transform import Rotation

    from physmocap.markers.functional import kabsch

    rng = np.random.default_rng(0)
    A = rng.normal(size=(5, 3))
    R = Rotation.from_euler("zyx", [30, -20, 10], degrees=True).as_matrix()
    t = np.array([0.1, 0.2, -0.3])
    X = (A @ R.T + t)[None]
    Rf, tf = kabsch(A, X, np.ones((1, 5)))
    assert np.allclose(Rf[0], R) and np.allclose(tf[0], t)


def _knee_twice(F: int = 200, swap: bool = False, spoil: str = "gaps"):
    """The standing markers with a second lateral knee marker, ``LFLE`` (Qualisys's name), 3 mm
    from ``LKNE``; ``LKNE`` is spoilt (``"gaps"``: missing in 60 % of frames; ``"jumps"``: 8 cm
    off in a third of them, a ghost), and ``LFLE`` comes first in the file with ``swap``."""
    from pathlib import Path

    from physmocap.markers.recording import MarkerRecording

    labels, P, _ = _standing_markers(F)
    k = labels.index("LKNE")
    P = np.concatenate([P, (P[:, k] + [0.0, 0.003, 0.0])[:, None]], axis=1)
    labels = labels + ["LFLE"]
    if spoil == "gaps":
        P[: int(0.6 * F), k] = np.nan
    else:
        P[::3, k] += [0.0, 0.0, 0.08]
    if swap:
        order = list(range(len(labels)))
        order[k], order[-1] = order[-1], order[k]
        P, labels = P[:, order], [labels[i] for i in order]
    return MarkerRecording(tuple(labels), P, 100.0, Path("knee.trc"))


@pytest.mark.parametrize("spoil", ["gaps", "jumps"])
@pytest.mark.parametrize("swap", [False, True])
def test_two_labels_for_one_role_the_consistent_one_plays_it(spoil, swap):
    """LKNE and LFLE are both the lateral knee: the one seen and rigid with the thigh's other
    markers in more frames plays the role, whichever comes first; one warning states it."""
    from physmocap.markers.markerset import recording_marker_set

    rec = _knee_twice(spoil=spoil, swap=swap)
    first, second = ("LFLE", "LKNE") if swap else ("LKNE", "LFLE")
    with pytest.warns(PhysmocapWarning, match=rf"knee\.trc: {first} and {second} are all read as LKNE; LFLE is used, "
                      r"rigid with LKNEM in the most frames: LFLE: 200 of 200 frames consistent") as caught:
        ms = recording_marker_set(rec)
    assert len([w for w in caught if "read as LKNE" in str(w.message)]) == 1
    assert rec.labels[ms.roles["LKNE"]] == "LFLE" and "LKNE" in ms.unused
    seen = 80 if spoil == "gaps" else 200
    consistent = 80 if spoil == "gaps" else 133
    assert f"LKNE: {consistent} of 200 frames consistent ({seen} seen" in ms.choices["LKNE"]


def test_a_marker_set_file_decides_between_two_labels(tmp_path):
    import warnings

    from physmocap.markers.markerset import detect_marker_set, recording_marker_set

    rec = _knee_twice()
    assert detect_marker_set(rec.labels).candidates == {"LKNE": (rec.labels.index("LKNE"), rec.labels.index("LFLE"))}
    path = tmp_path / "set.toml"
    path.write_text('[markers]\nLKNE = "LKNE"\n')
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ms = recording_marker_set(rec, path)
    assert rec.labels[ms.roles["LKNE"]] == "LKNE" and not ms.choices
    # a file giving one of them another role leaves no choice: one marker, one role
    path.write_text('[markers]\nLKNEM = "LFLE"\n')
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ms = recording_marker_set(rec, path)
    assert rec.labels[ms.roles["LKNE"]] == "LKNE" and rec.labels[ms.roles["LKNEM"]] == "LFLE" and not ms.choices


def test_inspect_states_which_of_two_labels_was_used(tmp_path, capsys):
    from physmocap.cli import main

    rec = _knee_twice(60)
    path = tmp_path / "knee.trc"
    _write_trc(path, list(rec.labels), np.nan_to_num(rec.positions) * 1000)
    with pytest.warns(PhysmocapWarning, match="LFLE is used"):
        assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    assert "chosen:    LKNE and LFLE are all read as LKNE; LFLE is used" in out and "LKNE=LFLE" in out
    with pytest.warns(PhysmocapWarning, match="LFLE is used"):
        assert main(["inspect", str(path), "--emit-markerset"]) == 0
    assert "# LKNE: LKNE and LFLE are all read as LKNE; LFLE is used" in capsys.readouterr().out
