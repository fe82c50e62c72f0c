"""`physmocap batch` (issue 14, first part): a folder of clips, resumable, parallel, Ray."""

from __future__ import annotations

import json
import os
import time

import pytest

from conftest import example_clip_folder
from physmocap.cli import main


@pytest.fixture()
def folder(tmp_path):
    example_clip_folder(tmp_path)
    (tmp_path / "in" / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    return tmp_path


def _batch(folder, out, *extra):
    return main(["batch", str(folder / "in"), "-o", str(folder / out), "--end", "40", "--quiet", *extra])


def _files(root):
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file() and p.name != "timings.csv"
            and not p.name.startswith(".")}


def test_batch_records_failures_and_mirrors_outputs(folder):
    assert _batch(folder, "out", "--jobs", "1") == 1  # one file failed
    out = folder / "out"
    assert (out / "a.npz").exists() and (out / "sub" / "b.npz").exists() and not (out / "broken.npz").exists()
    summary = json.loads((out / "summary.json").read_text())
    rows = {r["input"]: r for r in summary["files"]}
    assert rows[os.path.join("..", "in", "broken.bvh")]["status"] == "failed"
    assert "broken.bvh" in rows[os.path.join("..", "in", "broken.bvh")]["error"]
    # the summaries name files relatively, in their errors too (the machine's paths stay out)
    assert str(folder) not in (out / "summary.json").read_text() + (out / "summary.csv").read_text()
    assert rows[os.path.join("..", "in", "a.bvh")]["frames"] == 39
    done = rows[os.path.join("..", "in", "a.bvh")]
    assert isinstance(done["pop_frames"], int) and done["largest_pop_cm"] >= 0.0  # the fidelity's pops
    assert summary["totals"] == {"files": 3, "done": 2, "failed": 1, "frames": 78}


def test_batch_resumes_and_is_the_same_with_more_workers(folder):
    assert _batch(folder, "one", "--jobs", "1") == 1
    first = _files(folder / "one")
    stamp = (folder / "one" / "a.npz").stat().st_mtime_ns
    time.sleep(0.01)
    assert _batch(folder, "one", "--jobs", "1") == 1  # done files are skipped, the failure retried
    assert (folder / "one" / "a.npz").stat().st_mtime_ns == stamp
    assert _files(folder / "one") == first
    assert _batch(folder, "one", "--jobs", "1", "--force") == 1
    assert (folder / "one" / "a.npz").stat().st_mtime_ns != stamp
    assert _batch(folder, "two", "--jobs", "2") == 1
    assert _files(folder / "two") == first
    # other options: the file is redone
    assert _batch(folder, "one", "--jobs", "1", "--no-plant") == 1
    assert _files(folder / "one") != first


def test_output_folder_inside_the_input_folder_is_not_read_back(folder):
    out = folder / "in" / "out"
    args = ["batch", str(folder / "in"), "-o", str(out), "--end", "40", "--quiet", "--jobs", "1", "--format", "csv"]
    assert main(args) == 1  # broken.bvh
    first = _files(out)
    assert main(args) == 1  # its own CSV outputs and summary.csv are not taken as inputs
    assert _files(out) == first
    assert json.loads((out / "summary.json").read_text())["totals"]["files"] == 3


def test_batch_on_ray_gives_the_same_files(folder):
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'physmocap[cluster]'")
    assert _batch(folder, "local", "--jobs", "1") == 1
    assert _batch(folder, "ray", "--ray", "local") == 1
    assert _files(folder / "ray") == _files(folder / "local")


def test_batch_bad_source_is_one_clear_error(tmp_path, capsys):
    assert main(["batch", str(tmp_path / "nothing"), "-o", str(tmp_path / "o")]) == 2
    assert "folder, a glob" in capsys.readouterr().err


def _manifest(folder, name, text):
    path = folder / "in" / name
    path.write_text(text)
    return path


def test_csv_manifest_per_file_options_and_outputs(folder):
    manifest = _manifest(folder, "list.csv", "input,output,end,no-plant\na.bvh,../named/a_short.bvh,20,true\nsub/b.bvh,,30,\n")
    assert main(["batch", str(manifest), "-o", str(folder / "out"), "--quiet", "--jobs", "1"]) == 0
    assert (folder / "named" / "a_short.bvh").exists()  # relative to the manifest
    rows = {r["output"]: r for r in json.loads((folder / "out" / "summary.json").read_text())["files"]}
    assert rows[os.path.join("..", "named", "a_short.bvh")]["frames"] == 19  # --end 20, frame 0 skipped
    assert rows[os.path.join("sub", "b.npz")]["frames"] == 29  # mirrored under OUTDIR
    assert rows[os.path.join("..", "named", "a_short.bvh")]["skating_mean_cm_s"] is None  # --no-plant
    assert rows[os.path.join("sub", "b.npz")]["skating_mean_cm_s"] is not None


def test_jsonl_manifest_redoes_only_the_file_whose_options_changed(folder):
    lines = ['{"input": "a.bvh", "end": 25}', '# a comment', '{"input": "sub/b.bvh", "output": "b.npz", "end": 25}']
    manifest = _manifest(folder, "list.jsonl", "\n".join(lines) + "\n")
    run = ["batch", str(manifest), "-o", str(folder / "out"), "--quiet", "--jobs", "1"]
    assert main(run) == 0
    a, b = folder / "out" / "a.npz", folder / "in" / "b.npz"
    stamps = (a.stat().st_mtime_ns, b.stat().st_mtime_ns)
    time.sleep(0.01)
    assert main(run) == 0  # nothing to redo
    assert (a.stat().st_mtime_ns, b.stat().st_mtime_ns) == stamps
    lines[2] = '{"input": "sub/b.bvh", "output": "b.npz", "end": 25, "max_iterations": 3}'
    manifest.write_text("\n".join(lines) + "\n")
    assert main(run) == 0
    assert a.stat().st_mtime_ns == stamps[0] and b.stat().st_mtime_ns != stamps[1]


@pytest.mark.parametrize(
    "name, text, message",
    [
        ("m.csv", "input,speed\na.bvh,3\n", "m.csv:2: unknown option 'speed'"),
        ("m.csv", "input,max-iterations\na.bvh,0\n", "m.csv:2: --max-iterations must be at least 1"),
        ("m.jsonl", '{"input": "a.bvh"}\n{"input": "a.bvh", "start": "x"}\n', "m.jsonl:2: argument --start: invalid int"),
        ("m.jsonl", '{"input": "a.bvh", "no-plant": "maybe"}\n', "m.jsonl:1: --no-plant is a flag"),
        ("m.csv", "input,start,end\na.bvh,30,10\n", "m.csv:2: --start 30 --end 10: the range is empty"),
        ("m.csv", "output\nx.npz\n", "m.csv:1: a CSV manifest starts with a header row naming an 'input' column"),
        ("m.jsonl", '{"input": "a.bvh"}\n{"input": "a.bvh"}\n', "lines 1 and 2 would write the same output"),
        ("m.csv", "input\nnope.bvh\n", "m.csv:2: input "),
        ("m.jsonl", '{"input": "a.bvh", "fps": "nan"}\n', "m.jsonl:1: --fps: the frame rate must be a number in (0, 2000]"),
        ("m.jsonl", '{"input": "a.bvh", "output": "a.bvh"}\n', "m.jsonl:1: the output "),
        ("m.jsonl", '{"input": "a.bvh", "output": "/proc/x.npz"}\n', "m.jsonl:1: output '/proc/x.npz'"),
        ("m.jsonl", '{"input": "a.bvh", "output": "a.bvh/x.npz"}\n', "m.jsonl:1: output "),
        ("m.csv", 'input,"end\na.bvh,3\n', "not a well-formed CSV row: unexpected end of data"),
        ("m.csv", "input\n", "m.csv: the manifest lists no input"),
        ("m.jsonl", "\n# nothing\n", "m.jsonl: the manifest lists no input"),
        ("m.jsonl", '["a.bvh"]\n', "m.jsonl:1: expected a JSON object, found list"),
        ("m.jsonl", '{"input": "a.bvh"', "m.jsonl:1: not a JSON object"),
    ],
)
def test_manifest_errors_name_the_line(folder, capsys, name, text, message):
    manifest = _manifest(folder, name, text)
    assert main(["batch", str(manifest), "-o", str(folder / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (folder / "out").exists()


def test_manifest_not_utf8_names_the_line(folder, capsys):
    manifest = folder / "in" / "m.csv"
    manifest.write_bytes(b"input\na.bvh\nb\xff.bvh\n")
    assert main(["batch", str(manifest), "-o", str(folder / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "m.csv:3: not UTF-8" in err and "Traceback" not in err


def test_txt_manifest_and_path_options_are_relative_to_the_manifest(tmp_path):
    from physmocap.batch import read_manifest

    (tmp_path / "m.txt").write_text("\ufeff# clips\na.bvh\n\nsub/b.bvh\n", encoding="utf-8")
    assert [(e.line, e.input, e.options) for e in read_manifest(tmp_path / "m.txt")] == [
        (2, tmp_path / "a.bvh", {}), (4, tmp_path / "sub" / "b.bvh", {})]
    (tmp_path / "m.jsonl").write_text(
        '{"input": "a.bvh", "--character": "robot", "source_map": "maps/s.toml", "fps": 30, "no_floor": "yes"}\n'
        '{"input": "b.bvh", "character": "chars/c.xml", "up": "z"}\n')
    first, second = read_manifest(tmp_path / "m.jsonl")
    assert first.options == {"character": "robot", "source_map": str(tmp_path / "maps" / "s.toml"), "fps": 30.0,
                             "no_floor": True}
    assert second.options == {"character": str(tmp_path / "chars" / "c.xml"), "up": "z"}
    (tmp_path / "m.csv").write_text("input,source-map\na.bvh,-s.toml\n")  # a value that starts with "-"
    assert read_manifest(tmp_path / "m.csv")[0].options == {"source_map": str(tmp_path / "-s.toml")}


def test_non_finite_figures_never_reach_the_summary(folder, monkeypatch):
    import physmocap.metrics

    monkeypatch.setattr(physmocap.metrics, "penetration", lambda model, qpos: {"max_mm": float("nan")})
    assert _batch(folder, "out", "--jobs", "1") == 1
    text = (folder / "out" / "summary.json").read_text()
    rows = {r["input"]: r for r in json.loads(text)["files"]}
    assert rows[os.path.join("..", "in", "a.bvh")]["penetration_max_mm"] is None and "NaN" not in text


def test_a_folder_of_links_mirrors_the_links_names(folder):
    links = folder / "links"
    links.mkdir()
    for name in ("x.bvh", "y.bvh"):  # two links to one clip: two outputs
        (links / name).symlink_to(folder / "in" / "a.bvh")
    assert main(["batch", str(links), "-o", str(folder / "out"), "--end", "20", "--quiet", "--jobs", "1"]) == 0
    assert (folder / "out" / "x.npz").exists() and (folder / "out" / "y.npz").exists()


def test_a_failing_metric_fails_the_file(folder, monkeypatch):
    import physmocap.metrics

    def boom(model, qpos):
        raise RuntimeError("metric broke")

    monkeypatch.setattr(physmocap.metrics, "penetration", boom)
    assert _batch(folder, "out", "--jobs", "1") == 1
    rows = {r["input"]: r for r in json.loads((folder / "out" / "summary.json").read_text())["files"]}
    assert rows[os.path.join("..", "in", "a.bvh")]["status"] == "failed"
    assert "metric broke" in rows[os.path.join("..", "in", "a.bvh")]["error"]


def test_a_failed_file_is_named_once(folder, capsys):
    assert _batch(folder, "out") == 1
    err = capsys.readouterr().err
    broken = str(folder / "in" / "broken.bvh")
    line = next(x for x in err.splitlines() if x.startswith("failed:"))
    assert line.count(broken) == 1, line


def test_a_failed_file_is_named_as_the_user_spelt_the_source(folder, capsys, monkeypatch):
    """Before: a relative source folder's failures were named by absolute paths."""
    monkeypatch.chdir(folder)
    assert main(["batch", "in", "-o", "out", "--end", "40", "--quiet"]) == 1
    line = next(x for x in capsys.readouterr().err.splitlines() if x.startswith("failed:"))
    assert line.startswith(f"failed: {os.path.join('in', 'broken.bvh')}:") and str(folder) not in line, line


def test_bvh_options_for_a_batch_of_npz_are_said_to_be_ignored(tmp_path):
    """Before: ``batch ... --up Z`` writing NPZ files ran silently (each file's warning is not
    shown); it is said once for the batch."""
    import pytest

    from conftest import example_clip_folder
    from physmocap.cli import main

    src = example_clip_folder(tmp_path)
    with pytest.warns(UserWarning, match="--up applies to BVH outputs only"):
        assert main(["batch", str(src), "-o", str(tmp_path / "out"), "--up", "Z", "--jobs", "1", "--end", "8", "--quiet"]) == 0
