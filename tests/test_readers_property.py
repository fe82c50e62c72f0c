"""Issue 15: property tests for every reader, like the BVH ones (``test_bvh_property.py``).

Each reader gets random corruptions of a small valid file of its format (byte flips,
truncations, deleted or repeated lines, numbers replaced by extreme values).  A reader
either returns a motion (or mapping) whose numbers are finite, or raises one
:class:`~physmocap.errors.PhysmocapError` whose message names the file and fits on one
line; nothing else (no traceback, no other exception type).  Readers backed by native
code that may abort on corrupt input (C3D through ezc3d) are exercised out of process
by ``scripts/fuzz.py`` instead.
"""

from __future__ import annotations

import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from corruption import byte_edit
from physmocap.errors import PhysmocapError

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
_EXTREMES = [b"nan", b"inf", b"-inf", b"1e308", b"-1e308", b"9" * 60, b"0", b"-0", b"1e-300", b"", b"x"]


def _seeds() -> dict[str, bytes]:
    """Small valid files of every text/container format, made from the bundled clip."""
    from physmocap.export.mcap import write_motion_mcap
    from physmocap.sources import load_motion
    from physmocap.sources.synth import tracker_stream, write_stream_csv, write_stream_jsonl, write_stream_npz

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        walk = load_motion("example").slice_frames(1, 13)
        stream = tracker_stream(walk, layout="nite", fps=30.0, seed=3)
        out = {}
        with tempfile.TemporaryDirectory() as tmp:
            d = Path(tmp)
            out[".csv"] = write_stream_csv(stream, d / "s.csv").read_bytes()
            out[".jsonl"] = write_stream_jsonl(stream, d / "s.jsonl").read_bytes()
            out[".npz"] = write_stream_npz(stream, d / "s.npz").read_bytes()
            out[".mcap"] = write_motion_mcap(walk, d / "w.mcap").read_bytes()
    names = [n for n in walk.skeleton.names if not n.endswith("_End")][:6]
    P = walk.world_positions()[:4] * 1000.0
    lines = [
        "PathFileType\t4\t(X/Y/Z)\tseed.trc",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"120\t120\t4\t{len(names)}\tmm\t120\t1\t4",
        "Frame#\tTime\t" + "\t\t\t".join(names),
        "\t\t" + "\t".join(f"X{k + 1}\tY{k + 1}\tZ{k + 1}" for k in range(len(names))),
        "",
    ]
    for t in range(4):
        row = [str(t + 1), f"{t / 120:.5f}"] + [f"{v:.3f}" for j in range(len(names)) for v in P[t, j]]
        lines.append("\t".join(row))
    out[".trc"] = ("\n".join(lines) + "\n").encode()
    out[".toml"] = (Path(__file__).parents[1] / "assets" / "mjcf" / "robot.map.toml").read_bytes()
    return out


SEEDS = _seeds()


@st.composite
def corrupted(draw, suffix: str):
    data = bytearray(SEEDS[suffix])
    for _ in range(draw(st.integers(1, 4))):
        if not data:
            break
        kind = draw(st.sampled_from(["flip", "truncate", "del_line", "dup_line", "number"]))
        if kind == "number":
            import re

            spans = [m.span() for m in re.finditer(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?", bytes(data))]
            if spans:
                a, b = spans[draw(st.integers(0, len(spans) - 1))]
                data[a:b] = draw(st.sampled_from(_EXTREMES))
        else:
            data = bytearray(byte_edit(draw, bytes(data), kind))
    return bytes(data)


def _check_motion(m) -> None:
    """A motion that was read is usable: finite rate, and finite positions wherever the
    source vouches for them (lost tracker samples carry confidence 0)."""
    assert np.isfinite(m.fps) and m.fps > 0 and m.num_frames > 0
    if m.positions is None:
        assert np.isfinite(m.world_positions()).all()
        return
    finite = np.all(np.isfinite(m.positions), axis=-1)
    if m.confidence is None:
        assert finite.all()
    else:
        assert np.all(finite | (m.confidence <= 0.0))
        assert np.all(np.isfinite(m.confidence)) and np.all((m.confidence >= 0) & (m.confidence <= 1))


def _read(suffix: str, data: bytes) -> None:
    from physmocap.sources import load_motion

    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / f"corrupt{suffix}"
        p.write_bytes(data)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                if suffix == ".toml":
                    from physmocap.models.mapping import read_mapping

                    read_mapping(p)
                    return
                m = load_motion(p)
            except PhysmocapError as exc:
                msg = str(exc)
                assert str(p) in msg and "\n" not in msg, msg
                return
        _check_motion(m)


@pytest.mark.parametrize("suffix", [".csv", ".jsonl", ".npz", ".mcap", ".trc", ".toml"])
def test_seed_files_are_valid(suffix):
    _read(suffix, SEEDS[suffix])


@settings(max_examples=150, **SETTINGS)
@given(data=st.data())
def test_random_corruptions_fail_cleanly(data):
    suffix = data.draw(st.sampled_from(sorted(SEEDS)))
    _read(suffix, data.draw(corrupted(suffix)))
