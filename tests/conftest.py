"""Shared fixtures: the real recordings in ../shared/data, or in $PHYSMOCAP_SHARED_DATA (skipped where absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
#: Where SHARED_DATA came from, for skip reasons.
SHARED_DATA_ORIGIN = ("from PHYSMOCAP_SHARED_DATA" if "PHYSMOCAP_SHARED_DATA" in os.environ
                      else "the default ../shared/data; set PHYSMOCAP_SHARED_DATA to the recordings' folder")

SHARED_BVH = [
    "cmu_12_01_walk.bvh",
    "pymo_walk.bvh",
    "cmu_01_01_jumps.bvh",
    "optitrack_hops_crouch.bvh",
]
WALKS = ["cmu_12_01_walk.bvh", "pymo_walk.bvh"]


def load_script(name: str):
    """The module of ``scripts/<name>.py`` (the scripts are not a package), executed afresh."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


VENDOR_FIXTURES = REPO / "tests" / "fixtures" / "bvh"


def first_frames(name: str, count: int) -> bytes:
    """A vendor fixture's bytes cut to its first ``count`` frame rows (the ``Frames:`` line
    says so, in the file's own spacing): the parser tests that edit a file line by line
    work on a few frames; the fixtures themselves hold about 1.5 s of walking."""
    import re

    data = (VENDOR_FIXTURES / name).read_bytes()
    nl = b"\r\n" if b"\r\n" in data else b"\n"
    lines = data.split(nl)
    motion = next(i for i, line in enumerate(lines) if line.strip() == b"MOTION")
    head = lines[: motion + 3]
    head[motion + 1] = re.sub(rb"(Frames:\s*)\d+", rb"\g<1>%d" % count, head[motion + 1])
    return nl.join(head + lines[motion + 3: motion + 3 + count]) + nl


def shared_file(name: str) -> Path:
    """Path of a shared recording, or skip the test with a clear reason."""
    path = SHARED_DATA / name
    if not path.exists():
        pytest.skip(f"real recording {name} not found in {SHARED_DATA} ({SHARED_DATA_ORIGIN})")
    return path


@pytest.fixture(params=SHARED_BVH)
def shared_bvh(request) -> Path:
    return shared_file(request.param)


_RETARGET_CACHE: dict = {}


def retargeted(clip: str, character: str = "humanoid", **options):
    """Retarget a shared clip once per test session (cached by clip, character, options)."""
    key = (clip, character, tuple(sorted(options.items())))
    if key not in _RETARGET_CACHE:
        from physmocap.ik.retarget import retarget
        from physmocap.models import load_character
        from physmocap.sources import load_motion

        motion = load_motion(shared_file(clip))
        _RETARGET_CACHE[key] = (motion, retarget(motion, load_character(character), progress=False, **options))
    return _RETARGET_CACHE[key]


#: The retargeter's quality diagnostics (physmocap.metrics.fidelity's "does not follow / faces
#: away / velocity caps", the solver's "contact equalities softened", the skipped reference
#: pose): expected whenever a real clip (or garbage) is retargeted.  The tests about them assert
#: them with pytest.warns; modules that retarget real clips for another purpose mark themselves
#: ``pytestmark = RETARGET_DIAGNOSTICS`` to ignore exactly these messages, nothing else.
RETARGET_DIAGNOSTICS = pytest.mark.filterwarnings(
    *(
        f"ignore:{pattern}:physmocap.errors.PhysmocapWarning"
        for pattern in (
            r".*the character does not follow the actor",
            r".*the character faces more than \d+ degrees away from the actor",
            r".*joints move at their velocity caps on ",
            r".*the character jumps where the actor does not on ",
            r".*contact equalities softened on ",
            r".*frame 0 looks like a reference pose ",
        )
    )
)


def example_clip_folder(root: Path) -> Path:
    """``root/in`` holding the bundled example as ``a.bvh`` and ``sub/b.bvh`` (batch tests)."""
    import shutil

    from physmocap.resources import resolve_input

    src = resolve_input("example")
    (root / "in" / "sub").mkdir(parents=True)
    shutil.copy(src, root / "in" / "a.bvh")
    shutil.copy(src, root / "in" / "sub" / "b.bvh")
    return root
