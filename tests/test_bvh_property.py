"""Property-based BVH tests (hypothesis).

* Random valid files (random trees, several roots, any subset and order of the
  six channels on any joint, end sites, random formatting) read to the world
  positions an independent FK gives, and survive write -> read unchanged.
* Random corruptions of valid files give an InputError or a successful read
  (with warnings) of finite motion, never any other exception.
"""

from __future__ import annotations

import re
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from conftest import first_frames
from corruption import byte_edit, read_or_clean_error
from physmocap.errors import InputError, PhysmocapWarning
from physmocap.export.bvh import write_bvh
from physmocap.sources.bvh import CHANNEL_NAMES, read_bvh

FIXTURES = Path(__file__).parent / "fixtures" / "bvh"
SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)


@st.composite
def bvh_documents(draw):
    """(text, joints) for a random valid BVH file; joints hold the ground truth."""
    n = draw(st.integers(1, 7))
    joints = []
    for j in range(n):
        parent = -1 if j == 0 or draw(st.integers(0, 9)) == 0 else draw(st.integers(0, j - 1))
        chans = draw(st.permutations(CHANNEL_NAMES))
        chans = list(chans[: draw(st.integers(0, 6))])
        offset = [draw(st.sampled_from([0.0, 0.5, -3.25, 12.0, -40.0, 25.5, 7.125])) for _ in range(3)]
        joints.append({"parent": parent, "channels": chans, "offset": offset, "ends": []})
    if not any(j["channels"] for j in joints):
        joints[0]["channels"] = ["Yrotation"]
    for j in joints:
        for _ in range(draw(st.integers(0, 2))):
            j["ends"].append([draw(st.sampled_from([0.0, 4.0, -6.5, 10.0])) for _ in range(3)])
    F = draw(st.integers(1, 5))
    C = sum(len(j["channels"]) for j in joints)
    values = draw(
        st.lists(
            st.lists(st.floats(-720, 720, allow_nan=False).map(lambda v: round(v, 4)), min_size=C, max_size=C),
            min_size=F,
            max_size=F,
        )
    )
    style = draw(st.sampled_from(["\t", "  ", " \t"]))
    newline = draw(st.sampled_from(["\n", "\r\n"]))
    numfmt = draw(st.sampled_from(["{:.4f}", "{:.6e}", "{}"]))

    # Depth-first order = file order; children in index order.
    children = {j: [k for k in range(n) if joints[k]["parent"] == j] for j in range(n)}
    lines = ["HIERARCHY"]
    order = []

    def emit(j, depth):
        ind = style * depth
        kind = "ROOT" if joints[j]["parent"] < 0 else "JOINT"
        lines.append(f"{ind}{kind} j{j}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}{style}OFFSET " + " ".join(numfmt.format(v) for v in joints[j]["offset"]))
        chans = joints[j]["channels"]
        lines.append(f"{ind}{style}CHANNELS {len(chans)}" + "".join(" " + c for c in chans))
        order.append(j)
        for k in children[j]:
            emit(k, depth + 1)
        for e in joints[j]["ends"]:
            lines.extend([f"{ind}{style}End Site", f"{ind}{style}{{",
                          f"{ind}{style}{style}OFFSET " + " ".join(numfmt.format(v) for v in e),
                          f"{ind}{style}}}"])
        lines.append(f"{ind}}}")

    for r in [j for j in range(n) if joints[j]["parent"] < 0]:
        emit(r, 0)
    lines += ["MOTION", f"Frames: {F}", "Frame Time: 0.0333333"]
    # Values are drawn per joint in file order.
    lines += [" ".join(numfmt.format(v) for v in row) for row in values]
    return newline.join(lines) + newline, joints, order, np.array(values).reshape(F, C)


def _reference_world(joints, order, values):
    """World positions (file units, Y-up) of joints and end sites in file order."""
    F = values.shape[0]
    out = []
    for f in range(F):
        k = 0
        R, P, pts = {}, {}, []
        for j in order:
            t = np.array(joints[j]["offset"], dtype=float)
            axes, angles = "", []
            for c in joints[j]["channels"]:
                if c.endswith("position"):
                    t["XYZ".index(c[0])] = values[f, k]
                else:
                    axes += c[0]
                    angles.append(values[f, k])
                k += 1
            # one axis: a scalar angle (a 1-element list is a stack of one rotation on scipy < 1.11)
            ang = angles[0] if len(axes) == 1 else angles
            local = Rotation.from_euler(axes, ang, degrees=True).as_matrix() if axes else np.eye(3)
            p = joints[j]["parent"]
            if p < 0:
                P[j], R[j] = t, local
            else:
                P[j], R[j] = P[p] + R[p] @ t, R[p] @ local
        # File order puts a joint's end sites after its child joints; rebuild that order.
        def visit(j):
            pts.append(P[j])
            for c in [c for c in order if joints[c]["parent"] == j]:
                visit(c)
            for e in joints[j]["ends"]:
                pts.append(P[j] + R[j] @ np.array(e))

        for r in [j for j in order if joints[j]["parent"] < 0]:
            visit(r)
        out.append(pts)
    return np.array(out)


@pytest.mark.filterwarnings("ignore::physmocap.errors.PhysmocapWarning")
@settings(max_examples=60, **SETTINGS)
@given(doc=bvh_documents(), rotation_order=st.sampled_from([None, "ZXY", "XYZ", "YXZ"]),
       up=st.sampled_from([None, "Z"]))
def test_random_files_read_and_round_trip(doc, rotation_order, up):
    text, joints, order, values = doc
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "random.bvh"
        src.write_bytes(text.encode())
        m = read_bvh(src, units="cm", up="Y")  # random shapes: no up-axis detection
        ref = _reference_world(joints, order, values)
        M = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
        np.testing.assert_allclose(m.world_positions(), ref @ M.T * 0.01, atol=1e-9)

        out = Path(tmp) / "out.bvh"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PhysmocapWarning)  # layout widening when changing up
            write_bvh(m, out, rotation_order=rotation_order, up=up, precision=8)
        back = read_bvh(out, units="cm", up=up or "Y")
        assert back.skeleton.names == m.skeleton.names
        assert back.num_frames == m.num_frames
        size = max(float(np.ptp(ref.reshape(-1, 3), axis=0).max()) * 0.01, 0.01)
        np.testing.assert_allclose(back.world_positions(), m.world_positions(), atol=1e-6 * size)
        if rotation_order is None and up is None:
            assert back.meta["bvh_channels"] == m.meta["bvh_channels"]


# -- corruption ------------------------------------------------------------------------

_SEEDS = [(FIXTURES / "edge_cases.bvh").read_bytes()] + [
    first_frames(name, 5) for name in ("daz_poser.bvh", "optitrack_motive.bvh", "xsens_mvn.bvh")]
_VOCAB = [b"{", b"}", b"JOINT", b"ROOT", b"End", b"Site", b"OFFSET", b"CHANNELS", b"MOTION", b"Frames:",
          b"Frame", b"Time:", b"3", b"0", b"-1", b"1e5", b"nan", b"inf", b"Xrotation", b"Zposition",
          b"x", b"\xff", b"\x00", b"\n", b"\r", b"99999999999999999999", b"6", b"1e400", b".", b"-"]


@st.composite
def corrupted(draw):
    data = bytearray(draw(st.sampled_from(_SEEDS)))
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["delete", "insert", "replace", "truncate", "flip", "dup_line", "del_line"]))
        if not data:
            break
        if kind in ("delete", "insert", "replace"):
            toks = bytes(data).split(b" ")
            i = draw(st.integers(0, len(toks) - 1))
            if kind == "delete":
                del toks[i]
            elif kind == "insert":
                toks.insert(i, draw(st.sampled_from(_VOCAB)))
            else:
                toks[i] = draw(st.sampled_from(_VOCAB))
            data = bytearray(b" ".join(toks))
        else:
            data = bytearray(byte_edit(draw, bytes(data), kind))
    return bytes(data)


@settings(max_examples=250, **SETTINGS)
@given(data=corrupted())
def test_random_corruptions_fail_cleanly(data):
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "corrupt.bvh"
        p.write_bytes(data)
        m = read_or_clean_error(read_bvh, p)
        if m is None:
            return
        # The corruption left a valid file: the motion must be usable.
        assert np.isfinite(m.world_positions()).all()
        assert np.isfinite(m.fps) and m.fps > 0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PhysmocapWarning)
            write_bvh(m, Path(tmp) / "again.bvh")


def test_every_truncation_of_a_fixture(tmp_path):
    """Cut anywhere: in the hierarchy, or inside a row, an InputError naming the line;
    between rows a warning (Frames: disagrees) and exactly the complete rows."""
    data = first_frames("optitrack_motive.bvh", 5)
    rows_start = data.index(b"\n", data.index(b"Frame Time")) + 1
    (tmp_path / "full.bvh").write_bytes(data)
    full = read_bvh(tmp_path / "full.bvh")
    p = tmp_path / "t.bvh"
    for cut in range(0, len(data) + 1, 23):
        p.write_bytes(data[:cut])
        if cut < rows_start:
            with pytest.raises(InputError):
                read_bvh(p)
            continue
        body = data[rows_start:cut]
        complete = body.count(b"\n")
        tail = body.split(b"\n")[-1].split()
        if tail and not (len(tail) == 66 and re.fullmatch(rb"-?[0-9]+(\.[0-9]*)?", tail[-1])):
            with pytest.raises(InputError, match=r"t\.bvh:\d+: frame \d+: expected 66 numbers"):
                read_bvh(p)
            continue
        if tail:
            complete += 1  # cut inside the last number of a row: a full row (undetectable)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            m = read_bvh(p)
        assert m.num_frames == complete, cut
        if complete != 5:
            assert any(issubclass(w.category, PhysmocapWarning) for w in caught), cut
        whole = body.count(b"\n")  # rows before the cut are read exactly
        np.testing.assert_array_equal(m.rotations[:whole], full.rotations[:whole])