"""Shared fixtures: the real recordings in ../shared/data (skipped where absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))

SHARED_BVH = [
    "cmu_12_01_walk.bvh",
    "pymo_walk.bvh",
    "cmu_01_01_jumps.bvh",
    "optitrack_hops_crouch.bvh",
]
WALKS = ["cmu_12_01_walk.bvh", "pymo_walk.bvh"]


def shared_file(name: str) -> Path:
    """Path of a shared recording, or skip the test with a clear reason."""
    path = SHARED_DATA / name
    if not path.exists():
        pytest.skip(f"real recording {name} not found: ../shared/data is absent ({SHARED_DATA})")
    return path


@pytest.fixture(params=SHARED_BVH)
def shared_bvh(request) -> Path:
    return shared_file(request.param)
