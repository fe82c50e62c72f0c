"""`physmocap batch` robustness (issue 14): a worker process that dies, a manifest's character,
progress over files and frames, the failure's frame, the per-file option table, an
unreachable Ray address."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import sys
import time

import pytest

import physmocap.batch
from physmocap.batch import run_job
from conftest import example_clip_folder
from physmocap.cli import main


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


def _dies_once_before_starting(conn, func):
    """A pool process's entry for these tests: the first process (no marker file yet) takes
    its first job and exits before starting it, as one killed while idle would."""
    marker = os.environ["PHYSMOCAP_TEST_MARKER"]
    if not os.path.exists(marker):
        open(marker, "w").close()
        conn.recv()
        os._exit(4)
    physmocap.batch._worker_loop(conn, func)


@pytest.fixture()
def folder(tmp_path):
    example_clip_folder(tmp_path)
    return tmp_path


def _rows(out):
    return {os.path.basename(r["input"]): r for r in json.loads((out / "summary.json").read_text())["files"]}


def _batch(folder, *extra):
    return main(["batch", str(folder / "in"), "-o", str(folder / "out"), "--end", "40", "--quiet", *extra])


def test_a_dying_worker_fails_its_own_file_and_the_others_complete(folder, monkeypatch, capsys):
    for name in ("crash.bvh", "kill.bvh"):
        shutil.copy(folder / "in" / "a.bvh", folder / "in" / name)
    monkeypatch.setattr(physmocap.batch, "run_job", _exits_or_is_killed)
    # 4 files on 2 processes: both deaths need a new process for the files after them
    assert _batch(folder, "--jobs", "2") == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and "2 of 4 files done (78 frames)" in err
    rows = _rows(folder / "out")
    assert rows["crash.bvh"]["status"] == "failed" and rows["crash.bvh"]["frame"] is None
    assert rows["crash.bvh"]["error"] == "worker process died (exit code 3)"
    assert rows["kill.bvh"]["status"] == "failed" and rows["kill.bvh"]["frame"] == 5
    assert rows["kill.bvh"]["error"] == "worker process died (signal 9, SIGKILL)"
    assert f"failed: {folder / 'in' / 'kill.bvh'}: worker process died (signal 9, SIGKILL) (frame 5)" in err
    assert rows["a.bvh"]["status"] == rows["b.bvh"]["status"] == "done"
    assert rows["a.bvh"]["frames"] == rows["b.bvh"]["frames"] == 39
    assert (folder / "out" / "a.npz").exists() and (folder / "out" / "sub" / "b.npz").exists()


def test_a_job_whose_process_dies_before_starting_it_goes_to_the_next_process(folder, monkeypatch):
    monkeypatch.setenv("PHYSMOCAP_TEST_MARKER", str(folder / "died"))  # read by the test's own entry only
    monkeypatch.setattr(physmocap.batch, "_worker_loop", _dies_once_before_starting)
    assert _batch(folder, "--jobs", "2") == 0
    assert (folder / "died").exists()
    rows = _rows(folder / "out")
    assert rows["a.bvh"]["status"] == rows["b.bvh"]["status"] == "done"


def test_a_failure_while_retargeting_records_its_frame(folder, monkeypatch, capsys):
    from physmocap.ik.frame import FrameRetargeter

    solve, calls = FrameRetargeter.solve, []

    def fails_once(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 8:  # frame 7 of the first file (a.bvh)
            raise RuntimeError("solver broke")
        return solve(self, *args, **kwargs)

    monkeypatch.setattr(FrameRetargeter, "solve", fails_once)
    assert _batch(folder, "--jobs", "1") == 1
    rows = _rows(folder / "out")
    assert (rows["a.bvh"]["status"], rows["a.bvh"]["frame"]) == ("failed", 7)
    assert rows["a.bvh"]["error"] == "RuntimeError: solver broke"
    assert (rows["b.bvh"]["status"], rows["b.bvh"]["frame"]) == ("done", None)
    header = (folder / "out" / "summary.csv").read_text().splitlines()[0]
    assert header.startswith("input,output,status,error,frame,frames,")
    assert "RuntimeError: solver broke (frame 7)" in capsys.readouterr().err


def test_progress_counts_files_and_frames(folder, monkeypatch, capsys):
    monkeypatch.setenv("PHYSMOCAP_PROGRESS", "1")
    args = ["batch", str(folder / "in"), "-o", str(folder / "out"), "--end", "40", "--jobs", "1"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "batch: 2/2 files, 78 frames in " in err and "retarget" not in err


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


@pytest.mark.parametrize("via_environment", [False, True])
def test_an_unreachable_ray_address_is_one_error_within_seconds(folder, monkeypatch, capsys, via_environment):
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'physmocap[cluster]'")
    address = f"127.0.0.1:{_free_port()}"  # nothing listens there
    if via_environment:  # 'auto' joins RAY_ADDRESS first
        monkeypatch.setenv("RAY_ADDRESS", address)
    start = time.monotonic()
    assert _batch(folder, "--ray", "auto" if via_environment else address) == 2
    assert time.monotonic() - start < 30  # Ray's own retries take minutes
    err = capsys.readouterr().err
    option = f"--ray auto (RAY_ADDRESS={address})" if via_environment else f"--ray {address}"
    assert f"{option}: no Ray cluster answers there" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_a_web_server_at_the_ray_address_is_one_error_at_once(folder, capsys):
    """Something that listens but is no Ray cluster (a web server) left ray.init retrying for
    minutes: the probe's HTTP/2 handshake refuses it at once."""
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'physmocap[cluster]'")
    import http.server
    import threading

    class Quiet(http.server.BaseHTTPRequestHandler):
        def log_message(self, *args):  # the server's own request log is not the batch's stderr
            pass

    server = http.server.HTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        address = f"127.0.0.1:{server.server_address[1]}"
        start = time.monotonic()
        assert _batch(folder, "--ray", address) == 2
        assert time.monotonic() - start < 10
    finally:
        server.shutdown()
        server.server_close()
    err = capsys.readouterr().err
    assert f"--ray {address}: something listens there but it does not answer as a Ray cluster" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_an_unreadable_mcap_in_the_folder_fails_alone(folder, capsys):
    """A file whose type cannot be told (an .mcap that does not read) is one failed file of the
    summary, not the batch's end; a reader's error names its frame in the summary."""
    (folder / "in" / "garbage.mcap").write_bytes(b"\x00not an mcap file\n" * 40)
    bvh = (folder / "in" / "a.bvh").read_text().splitlines()
    first = next(i for i, line in enumerate(bvh) if line.startswith("Frame Time")) + 1
    row = bvh[first + 12].split()
    row[4] = "nan"
    bvh[first + 12] = " ".join(row)
    (folder / "in" / "nan.bvh").write_text("\n".join(bvh) + "\n")
    assert _batch(folder, "--jobs", "1") == 1
    rows = _rows(folder / "out")
    assert rows["garbage.mcap"]["status"] == "failed" and "not an MCAP file" in rows["garbage.mcap"]["error"]
    assert (rows["nan.bvh"]["status"], rows["nan.bvh"]["frame"]) == ("failed", 12)
    assert rows["a.bvh"]["status"] == rows["b.bvh"]["status"] == "done"


def test_a_batch_that_cannot_start_leaves_no_folder(folder, capsys):
    """An output folder that is a file is one error; a batch that fails before its first file
    (Ray unreachable) makes no output folder."""
    (folder / "file").write_text("")
    assert main(["batch", str(folder / "in"), "-o", str(folder / "file"), "--quiet"]) == 2
    assert "is a file: the outputs need a folder" in capsys.readouterr().err
    assert main(["batch", str(folder / "in"), "-o", str(folder / "new" / "out"), "--ray", f"127.0.0.1:{_free_port()}",
                 "--quiet"]) == 2
    assert not (folder / "new").exists()


def test_ray_is_shut_down_when_the_output_folder_cannot_be_made(folder, monkeypatch, capsys):
    """Ray is connected before the output folder is made (a batch that cannot reach Ray leaves
    no folder); a folder that then cannot be made still shuts the Ray session down."""
    import physmocap.batch as batch

    calls = []

    class FakeRay:
        @staticmethod
        def shutdown():
            calls.append("shutdown")

    monkeypatch.setattr(batch, "_ray_connect", lambda address: (FakeRay, True))
    (folder / "file").write_text("")
    assert main(["batch", str(folder / "in"), "-o", str(folder / "file" / "out"), "--ray", "local", "--quiet"]) == 2
    assert "cannot create the output folder" in capsys.readouterr().err
    assert calls == ["shutdown"]


def test_two_inputs_with_one_output_are_named(folder, capsys):
    (folder / "in" / "a.trc").write_text("")  # a.bvh's output too: the plan refuses before reading
    assert _batch(folder) == 2
    err = capsys.readouterr().err
    assert "a.bvh and " in err and "a.trc would write the same output" in err and "manifest" in err


def test_ray_refusing_to_connect_is_one_error(folder, monkeypatch, capsys):
    ray = pytest.importorskip("ray", reason="Ray is not installed: pip install 'physmocap[cluster]'")

    def refuse(*args, **kwargs):
        raise ConnectionError("Could not find any running Ray instance.\nPlease specify the one to connect to.")

    monkeypatch.setattr(ray, "init", refuse)
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert _batch(folder, "--ray", "auto") == 2
    err = capsys.readouterr().err
    assert "--ray auto: cannot connect to Ray: Could not find any running Ray instance." in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_a_dying_ray_worker_fails_its_own_file(folder, monkeypatch):
    ray = pytest.importorskip("ray", reason="Ray is not installed: pip install 'physmocap[cluster]'")
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # Ray's workers cannot import tests/
    shutil.copy(folder / "in" / "a.bvh", folder / "in" / "crash.bvh")
    monkeypatch.setattr(physmocap.batch, "run_job", _exits_or_is_killed)
    assert _batch(folder, "--ray", "local") == 1
    rows = _rows(folder / "out")
    assert rows["crash.bvh"]["status"] == "failed"
    assert rows["crash.bvh"]["error"].startswith("worker process died (Ray WorkerCrashedError")
    assert rows["a.bvh"]["status"] == rows["b.bvh"]["status"] == "done"
