"""`physmocap batch` robustness (issue 14): a worker process that dies, a manifest's character,
progress over files and frames, the failure's frame, the per-file option table, an
unreachable Ray address."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket

import pytest

from physmocap.batch import run_job
from physmocap.cli import main
from physmocap.resources import resolve_input


def _exits_or_is_killed(job, options, on_frames=None):
    """The worker's job function for these tests (module level: a spawned worker imports it):
    ``crash*.bvh`` exits at once with code 3; ``kill*.bvh`` is killed by SIGKILL (as the
    out-of-memory killer does) once its frame 5 is reached; any other file runs as usual."""
    name = os.path.basename(job.input)
    if name.startswith("crash"):
        os._exit(3)
    if not name.startswith("kill"):
        return run_job(job, options) if on_frames is None else run_job(job, options, on_frames)

    def frames(done, total):
        if on_frames is not None:
            on_frames(done, total)
        if done == 5:
            os.kill(os.getpid(), signal.SIGKILL)

    return run_job(job, options, frames)


@pytest.fixture()
def folder(tmp_path):
    src = resolve_input("example")
    (tmp_path / "in" / "sub").mkdir(parents=True)
    shutil.copy(src, tmp_path / "in" / "a.bvh")
    shutil.copy(src, tmp_path / "in" / "sub" / "b.bvh")
    return tmp_path


def _rows(out):
    return {os.path.basename(r["input"]): r for r in json.loads((out / "summary.json").read_text())["files"]}


def _batch(folder, *extra):
    return main(["batch", str(folder / "in"), "-o", str(folder / "out"), "--end", "40", "--quiet", *extra])


@pytest.mark.parametrize(
    "text, message",
    [
        ("input,character\na.bvh,\nsub/b.bvh,nope\n", "m.csv:3: character: nope: no such character; bundled characters are"),
        ("input,character\na.bvh,chars/bad.xml\n", "m.csv:2: character: "),
        ("input,map\na.bvh,none.map.toml\n", "m.csv:2: character: "),
    ],
)
def test_a_manifest_character_that_cannot_be_loaded_is_a_line_error(folder, capsys, text, message):
    (folder / "in" / "chars").mkdir()
    (folder / "in" / "chars" / "bad.xml").write_text("<mujoco><worldbody><body>\n")
    (folder / "in" / "m.csv").write_text(text)
    assert main(["batch", str(folder / "in" / "m.csv"), "-o", str(folder / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (folder / "out").exists()  # before any file runs


def test_the_batch_character_that_cannot_be_loaded_is_one_error(folder, capsys):
    assert _batch(folder, "--character", "nope") == 2
    err = capsys.readouterr().err
    assert "nope: no such character" in err and "Traceback" not in err
    assert not (folder / "out").exists()


def test_a_manifest_character_is_loaded_with_the_batch_map_it_does_not_give(folder):
    (folder / "in" / "m.csv").write_text("input,character\na.bvh,robot\nsub/b.bvh,robot\n")
    assert main(["batch", str(folder / "in" / "m.csv"), "-o", str(folder / "out"), "--end", "20", "--quiet",
                 "--jobs", "1"]) == 0


def test_the_per_file_option_table_is_retargets_options():
    from physmocap.batch import OptionTable
    from physmocap.cli.retarget import retarget_option_parser
    from physmocap.errors import OptionError

    table = OptionTable.build()
    assert set(table.actions) == set(vars(retarget_option_parser().parse_args([]))) - {"quiet"}
    assert table.lookup("--no-plant").dest == table.lookup("no_plant").dest == "no_plant"
    with pytest.raises(OptionError, match="unknown option 'quiet'"):
        table.lookup("quiet")


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


