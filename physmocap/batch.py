"""Whole datasets: retarget every file of a folder, glob or manifest, on local processes or Ray.

* :func:`plan` turns the inputs into :class:`Job` s, outputs mirrored under the output
  folder (``walks/a.bvh`` -> ``OUT/walks/a.<suffix>``).
* :func:`run_job` retargets one file in the current process and returns a
  :class:`FileResult` (never raises: a failure is recorded with its error).
* :func:`run_batch` runs the jobs on a process pool (``jobs`` workers, ``spawn`` start) or
  as Ray tasks, skips files already done (output newer than its input, same options),
  and writes ``summary.csv`` and ``summary.json`` (sorted by input, no timings: the same
  whatever the workers) and ``timings.csv``.

The options are the ``retarget`` command's, carried as a plain dict (JSON), so a worker on
another machine rebuilds exactly the same call.
"""

from __future__ import annotations

import csv
import glob as globlib
import hashlib
import json
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterable

from .errors import InputError, OptionError, PhysmocapError

__all__ = ["Job", "FileResult", "plan", "run_job", "run_batch", "SUMMARY_FIELDS"]

#: Input suffixes a folder or glob picks up.
INPUT_SUFFIXES = (".bvh", ".c3d", ".trc", ".mcap", ".csv", ".jsonl")
#: Columns of summary.csv, in order.
SUMMARY_FIELDS = (
    "input", "output", "status", "error", "frames", "fps", "limit_violations", "penetration_max_mm",
    "skating_mean_cm_s", "worst_segment_median_deg", "facing_p95_deg", "path_mean_cm", "saturated_share",
)
STATE_FILE = ".physmocap-batch.json"


@dataclass(frozen=True)
class Job:
    """One file to retarget: its input and mirrored output (absolute paths)."""

    input: str
    output: str


@dataclass
class FileResult:
    """What happened to one file (figures as in the report; None where not measured)."""

    input: str
    output: str
    status: str  # "done" (now or by an earlier run of the same batch) or "failed"
    error: str = ""
    frames: int = 0
    fps: float = 0.0
    limit_violations: int | None = None
    penetration_max_mm: float | None = None
    skating_mean_cm_s: float | None = None
    worst_segment_median_deg: float | None = None
    facing_p95_deg: float | None = None
    path_mean_cm: float | None = None
    saturated_share: float | None = None
    seconds: float = field(default=0.0, compare=False)


def _inputs(source: str) -> tuple[list[Path], Path]:
    """Files of a folder (recursively), a glob or a manifest, and the root they mirror from."""
    p = Path(source)
    if p.is_dir():
        files = sorted(f for f in p.rglob("*") if f.is_file() and f.suffix.lower() in INPUT_SUFFIXES)
        return files, p
    if any(ch in source for ch in "*?["):
        files = sorted(Path(f) for f in globlib.glob(source, recursive=True) if Path(f).is_file())
        root = Path(os.path.commonpath([str(f.parent) for f in files])) if files else Path(".")
        return files, root
    if p.is_file() and p.suffix.lower() == ".txt":  # manifest: one input path per line
        base = p.parent
        lines = [ln.strip() for ln in p.read_text(encoding="utf-8").splitlines()]
        files = [(base / ln) if not Path(ln).is_absolute() else Path(ln) for ln in lines if ln and not ln.startswith("#")]
        root = Path(os.path.commonpath([str(f.parent) for f in files])) if files else base
        return files, root
    raise InputError("expected a folder, a glob pattern or a manifest (.txt, one input per line)", path=p)


def plan(source: str, outdir: str | os.PathLike, suffix: str = ".npz") -> list[Job]:
    """The jobs for every input of ``source``, outputs mirrored under ``outdir``."""
    files, root = _inputs(source)
    if not files:
        raise InputError("no input files found (looked for " + ", ".join(INPUT_SUFFIXES) + ")", path=source)
    out = Path(outdir)
    jobs = []
    for f in files:
        rel = f.resolve().relative_to(root.resolve()) if f.resolve().is_relative_to(root.resolve()) else Path(f.name)
        jobs.append(Job(input=str(f.resolve()), output=str((out / rel).with_suffix(suffix).resolve())))
    return jobs


def options_key(options: dict[str, Any]) -> str:
    """A stable digest of the retarget options (resuming redoes a file when they change)."""
    return hashlib.sha256(json.dumps(options, sort_keys=True).encode()).hexdigest()[:16]


def run_job(job: Job, options: dict[str, Any]) -> FileResult:
    """Retarget one file with the ``retarget`` command's options; never raises."""
    import argparse
    import warnings

    from . import metrics
    from .cli.retarget import retarget_from_args, write_outputs

    start = time.perf_counter()
    res = FileResult(job.input, job.output, "failed")
    try:
        ns = argparse.Namespace(**{**options, "input": job.input, "quiet": True})
        Path(job.output).parent.mkdir(parents=True, exist_ok=True)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            traj = retarget_from_args(ns)
            write_outputs(traj, [Path(job.output)], ns, quiet=True)
        ch = traj.character
        fid = traj.fidelity
        res.status = "done"
        res.frames, res.fps = int(traj.num_frames), float(traj.fps)
        res.limit_violations = int(metrics.joint_limit_violations(ch.model, traj.qpos)["count"])
        res.penetration_max_mm = round(float(metrics.penetration(ch.model, traj.qpos)["max_mm"]), 3)
        if traj.contacts is not None:
            res.skating_mean_cm_s = round(float(metrics.character_skating(traj)["mean_cm_s"]), 3)
        if fid is not None:
            res.worst_segment_median_deg = round(float(fid.worst_segment_median_deg), 2)
            res.facing_p95_deg = None if fid.facing_p95_deg is None else round(float(fid.facing_p95_deg), 2)
            res.path_mean_cm = None if fid.path_mean_cm is None else round(float(fid.path_mean_cm), 2)
            res.saturated_share = round(float(fid.saturated_share), 4)
    except PhysmocapError as exc:
        res.error = str(exc)
    except Exception as exc:  # noqa: BLE001 - one file's failure must not stop the dataset
        res.error = f"{type(exc).__name__}: {exc}".splitlines()[0][:300]
    res.seconds = time.perf_counter() - start
    return res


def _load_state(outdir: Path) -> dict[str, dict]:
    """Input -> {"key": options digest, "result": its FileResult} of the files done before."""
    try:
        data = json.loads((outdir / STATE_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict):
        return {}
    return {str(k): v for k, v in data.items() if isinstance(v, dict) and isinstance(v.get("result"), dict)}


def _done(job: Job, key: str, state: dict[str, dict]) -> bool:
    out, inp = Path(job.output), Path(job.input)
    entry = state.get(job.input)
    return (
        entry is not None
        and entry.get("key") == key
        and out.exists()
        and inp.exists()
        and out.stat().st_mtime >= inp.stat().st_mtime
    )


def _execute(jobs: list[Job], options: dict[str, Any], workers: int, ray: str | None) -> Iterable[FileResult]:
    """Results as they complete (local process pool, or Ray tasks)."""
    if ray is not None:
        try:
            import ray as ray_mod
        except ImportError:
            raise OptionError("--ray needs Ray: pip install 'physmocap[cluster]'") from None
        started = not ray_mod.is_initialized()
        if started:
            ray_mod.init(address=None if ray == "local" else ray, include_dashboard=False, log_to_driver=False)
        try:
            task = ray_mod.remote(run_job)
            pending = [task.remote(j, options) for j in jobs]
            while pending:
                ready, pending = ray_mod.wait(pending, num_returns=1)
                yield ray_mod.get(ready[0])
        finally:
            if started:
                ray_mod.shutdown()
        return
    if workers <= 1:
        for j in jobs:
            yield run_job(j, options)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(run_job, j, options) for j in jobs]
        for f in as_completed(futures):
            yield f.result()


def run_batch(
    jobs: list[Job],
    outdir: str | os.PathLike,
    options: dict[str, Any],
    *,
    workers: int = 1,
    force: bool = False,
    ray: str | None = None,
    progress: bool | None = None,
) -> list[FileResult]:
    """Run the jobs, skip those already done, write the summaries; results sorted by input."""
    from .fileio import atomic_open
    from .progress import Progress

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    key = options_key(options)
    state = {} if force else _load_state(out)
    todo = [j for j in jobs if force or not _done(j, key, state)]
    # files done by an earlier run keep their figures (the summary is the same either way)
    results = {}
    for j in jobs:
        if j not in todo:
            kept = {k: v for k, v in state[j.input]["result"].items() if k in FileResult.__dataclass_fields__}
            results[j.input] = FileResult(**{**kept, "seconds": 0.0})
    with Progress(len(todo), "batch", enabled=progress) as bar:
        for res in _execute(todo, options, workers, ray):
            results[res.input] = res
            if res.status == "done":
                state[res.input] = {"key": key, "result": asdict(res)}
            else:
                state.pop(res.input, None)
            with atomic_open(out / STATE_FILE) as fh:  # after every file: a killed batch resumes
                json.dump(state, fh, sort_keys=True, indent=0)
            bar.update(1)
    ordered = [results[j.input] for j in sorted(jobs, key=lambda j: j.input)]
    _write_summaries(ordered, out)
    return ordered


def _relative(path: str, root: Path) -> str:
    try:
        return os.path.relpath(path, root)
    except ValueError:
        return path


def _write_summaries(results: list[FileResult], out: Path) -> None:
    """summary.csv, summary.json and timings.csv, renamed into place together."""
    from .fileio import OutputSet

    with OutputSet():
        _write_summary_files(results, out)


def _write_summary_files(results: list[FileResult], out: Path) -> None:
    from .fileio import atomic_open

    rows = []
    for r in results:
        row = {k: v for k, v in asdict(r).items() if k in SUMMARY_FIELDS}
        row["input"], row["output"] = _relative(r.input, out), _relative(r.output, out)
        rows.append(row)
    done = [r for r in results if r.status == "done"]
    totals = {
        "files": len(results),
        "done": sum(r.status == "done" for r in results),
        "failed": sum(r.status == "failed" for r in results),
        "frames": sum(r.frames for r in done),
    }
    with atomic_open(out / "summary.csv", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(SUMMARY_FIELDS), lineterminator="\n")
        w.writeheader()
        for row in rows:
            w.writerow({k: "" if row[k] is None else row[k] for k in SUMMARY_FIELDS})
    with atomic_open(out / "summary.json") as fh:
        json.dump({"files": rows, "totals": totals}, fh, indent=2, sort_keys=True, allow_nan=False)
        fh.write("\n")
    with atomic_open(out / "timings.csv", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["input", "status", "frames", "seconds"])
        for r in results:
            w.writerow([_relative(r.input, out), r.status, r.frames, f"{r.seconds:.3f}"])
