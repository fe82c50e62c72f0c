"""Random corruptions of the real marker files: each reads (what is left is a valid
recording: NaN gaps, positive rate) or fails with one InputError naming the file, never
another exception (issue 11: "property tests over random corruptions as for BVH")."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import shared_file
from corruption import byte_edit, read_or_clean_error
from physmocap.errors import InputError

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
                derandomize=True)


@pytest.mark.parametrize("name,suffix", [("vicon_upperbody.trc", ".trc"), ("vicon_upperbody_box.c3d", ".c3d")])
@settings(max_examples=40, **SETTINGS)
@given(data=st.data())
def test_random_corruptions_of_marker_files_fail_cleanly(name, suffix, data):
    from physmocap.sources.c3d import read_c3d_markers
    from physmocap.sources.trc import read_trc_markers

    src = shared_file(name).read_bytes()
    kinds = ["truncate", "flip"] + (["dup_line", "del_line"] if suffix == ".trc" else [])
    edited = byte_edit(data.draw, src, data.draw(st.sampled_from(kinds)))
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / f"corrupt{suffix}"
        p.write_bytes(edited)
        rec = read_or_clean_error(read_c3d_markers if suffix == ".c3d" else read_trc_markers, p)
    if rec is not None:  # what is left is a valid recording
        assert rec.num_frames > 0 and np.isfinite(rec.fps) and rec.fps > 0
        assert len(rec.labels) == rec.positions.shape[1] and all(rec.labels)
        assert not np.isinf(rec.positions).any()


@pytest.mark.parametrize("cut", [0, 1, 300, 513, 821, 5000])
def test_c3d_cut_in_its_header_or_parameters_is_an_error_not_a_hang(tmp_path, cut):
    """ezc3d loops forever on a C3D file cut inside its parameter section (821 bytes of the
    box take did): the reader refuses it first."""
    from physmocap.sources.c3d import read_c3d_markers

    p = tmp_path / "cut.c3d"
    p.write_bytes(shared_file("vicon_upperbody_box.c3d").read_bytes()[:cut])
    with pytest.raises(InputError, match=r"cut\.c3d: (empty file|not a C3D file|truncated C3D file)"):
        read_c3d_markers(p)
