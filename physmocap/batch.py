"""Whole datasets: retarget every file of a folder, glob or manifest, on local processes or Ray.

* :func:`plan` turns the inputs into :class:`Job` s, outputs mirrored under the output
  folder (``walks/a.bvh`` -> ``OUT/walks/a.<suffix>``).  A manifest (:func:`read_manifest`:
  ``.txt``, one input a line; ``.csv`` or ``.jsonl`` with ``input``, optional ``output`` and
  per-file ``retarget`` options) may name each file's output and options.
* :func:`run_job` retargets one file in the current process and returns a
  :class:`FileResult` (never raises: a failure is recorded with its error and frame).
* :func:`run_batch` runs the jobs on worker processes (``jobs`` of them, ``spawn`` start;
  one that dies fails its own file and is replaced) or as Ray tasks, skips files already
  done (output newer than its input, same options, per-file ones included),
  and writes ``summary.csv`` and ``summary.json`` (sorted by input, no timings: the same
  whatever the workers) and ``timings.csv``.

The options are the ``retarget`` command's, carried as a plain dict (JSON), so a worker on
another machine rebuilds exactly the same call.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import glob as globlib
import hashlib
import io
import json
import math
import os
import signal
import time
from dataclasses import asdict, dataclass, field
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any, Callable, Iterator

from .errors import InputError, OptionError, OutputError, PhysmocapError
from .fileio import check_output_dir, read_text

__all__ = ["Job", "FileResult", "ManifestEntry", "OptionTable", "plan", "read_manifest", "run_job", "run_batch", "SUMMARY_FIELDS"]

#: Input suffixes a folder or glob picks up.
INPUT_SUFFIXES = (".bvh", ".c3d", ".trc", ".mcap", ".csv", ".jsonl")
#: Manifest suffixes: one input a line (.txt), or a table with per-file options (.csv, .jsonl).
MANIFEST_SUFFIXES = (".txt", ".csv", ".jsonl")
#: Largest manifest read (bytes): a line per file, so a million files fit.
MAX_MANIFEST_BYTES = 256 << 20
#: Output suffixes a manifest's ``output`` may have.
OUTPUT_SUFFIXES = (".npz", ".bvh", ".csv", ".mcap")
#: Per-file options that name files (relative to the manifest); ``character`` only when it
#: is a path (has a suffix or a folder), not a bundled name.
PATH_OPTIONS = ("map", "source_map", "marker_set", "contacts", "character")
#: Columns of summary.csv, in order.
SUMMARY_FIELDS = (
    "input", "output", "status", "error", "frame", "frames", "fps", "limit_violations", "penetration_max_mm",
    "skating_mean_cm_s", "worst_segment_median_deg", "facing_p95_deg", "path_mean_cm", "saturated_share",
    "pop_frames", "largest_pop_cm",
)
STATE_FILE = ".physmocap-batch.json"
#: Seconds a worker process is given to exit once told to (or once its pipe closed).
WORKER_EXIT_SECONDS = 10.0
#: Seconds to wait for a Ray address to answer before giving up.
RAY_CONNECT_SECONDS = 5.0
#: An HTTP/2 client's connection preface and an empty SETTINGS frame (RFC 9113, 3.4 and 6.5):
#: what :func:`_probe` sends a Ray address to see a gRPC server answer.
HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])


@dataclass(frozen=True)
class Job:
    """One file to retarget: its input and output (absolute paths), and the options that
    differ for this file from the batch's (``retarget``'s option names as argparse
    destinations, ``no_plant``, ``max_iterations``...; a manifest line's)."""

    input: str
    output: str
    options: dict[str, Any] = field(default_factory=dict, hash=False)


@dataclass(frozen=True)
class ManifestEntry:
    """One line of a manifest: its number (1-based; 0 for a file of a folder or glob),
    input, output (None: mirrored) and per-file options (argparse destinations to values)."""

    line: int
    input: Path
    output: Path | None
    options: dict[str, Any]


@dataclass
class FileResult:
    """What happened to one file (figures as in the report; None where not measured)."""

    input: str
    output: str
    status: str  # "done" (now or by an earlier run of the same batch) or "failed"
    error: str = ""
    frame: int | None = None  # where a failure happened, when known (see run_job)
    frames: int = 0
    fps: float = 0.0  # the clip's frame rate (frames/s), rounded to 4 decimals
    limit_violations: int | None = None
    penetration_max_mm: float | None = None
    skating_mean_cm_s: float | None = None
    worst_segment_median_deg: float | None = None
    facing_p95_deg: float | None = None
    path_mean_cm: float | None = None
    saturated_share: float | None = None
    pop_frames: int | None = None  # frames on which a joint jumps where the actor's does not
    largest_pop_cm: float | None = None
    seconds: float = field(default=0.0, compare=False)


def _inputs(source: str, outdir: Path) -> tuple[list[ManifestEntry], Path]:
    """Entries for the files of a folder (recursively), a glob or a manifest, and the root
    their mirrored outputs start from.  A folder or glob skips the files under ``outdir``
    (an output folder inside the input folder: its outputs and summaries are not inputs)."""
    p = Path(source)
    out = outdir.resolve()

    def _ours(f: Path) -> bool:
        return f.resolve().is_relative_to(out)

    if p.is_dir():
        files = sorted(f for f in p.rglob("*") if f.is_file() and f.suffix.lower() in INPUT_SUFFIXES and not _ours(f))
        return [ManifestEntry(0, f, None, {}) for f in files], p
    if any(ch in source for ch in "*?["):
        files = sorted(Path(f) for f in globlib.glob(source, recursive=True) if Path(f).is_file() and not _ours(Path(f)))
        root = Path(os.path.commonpath([str(f.parent) for f in files])) if files else Path(".")
        return [ManifestEntry(0, f, None, {}) for f in files], root
    if p.is_file() and p.suffix.lower() in MANIFEST_SUFFIXES:
        entries = read_manifest(p)
        if not entries:
            raise InputError("the manifest lists no input", path=p)
        root = Path(os.path.commonpath([str(e.input.parent) for e in entries])) if entries else p.parent
        return entries, root
    if not p.exists():
        raise InputError("not found: expected a folder, a glob pattern or a manifest", path=p)
    raise InputError(
        "expected a folder, a glob pattern or a manifest (.txt: one input a line; .csv or .jsonl: "
        "input, output and per-file options)",
        path=p,
    )


def read_manifest(path: str | os.PathLike, table: "OptionTable | None" = None) -> list[ManifestEntry]:
    """The entries of a manifest, paths relative to its folder made absolute.

    ``.txt``: one input a line (blank lines and ``#`` comments skipped).  ``.csv``: a header
    row naming ``input``, optionally ``output``, and per-file options; an empty cell is an
    option not given.  ``.jsonl``: one JSON object a line with the same keys (blank lines
    and ``#`` comments skipped; ``null`` is not given).  Option names are ``retarget``'s
    command-line options (``no-plant``, ``max-iterations``, ``start``...; a leading ``--``
    and ``_`` for ``-`` accepted); flags take true/false, 1/0 or yes/no.  Values are parsed
    by ``retarget``'s own options (``table``, default :meth:`OptionTable.build`).

    Raises:
        InputError: The manifest cannot be read, a line is not well-formed or has no input.
        OptionError: An unknown option or a bad value (naming the manifest and line).
    """
    p = Path(path)
    table = table or OptionTable.build()
    # a spreadsheet's CSV may start with a byte-order mark: read_text drops it, and names the
    # line of a byte that is not UTF-8
    text = read_text(p, "manifest", limit=MAX_MANIFEST_BYTES)
    suffix = p.suffix.lower()
    rows = _txt_rows(text) if suffix == ".txt" else _csv_rows(text, p) if suffix == ".csv" else _jsonl_rows(text, p)
    return [_entry(line, row, p, table) for line, row in rows]


def _txt_rows(text: str) -> list[tuple[int, dict[str, Any]]]:
    """``(line, {"input": path})`` per non-blank, non-comment line."""
    lines = [(n, ln.strip()) for n, ln in enumerate(text.splitlines(), start=1)]
    return [(n, {"input": ln}) for n, ln in lines if ln and not ln.startswith("#")]


def _csv_rows(text: str, path: Path) -> list[tuple[int, dict[str, Any]]]:
    """``(line, {column: cell})`` per non-blank row; empty cells left out."""
    reader = csv.reader(io.StringIO(text), strict=True)
    try:
        return _csv_table(reader, path)
    except csv.Error as exc:  # an unterminated quote...
        raise InputError(f"not a well-formed CSV row: {exc}", path=path, line=reader.line_num) from None


def _csv_table(reader: Any, path: Path) -> list[tuple[int, dict[str, Any]]]:
    """The rows of :func:`_csv_rows` from a ``csv.reader`` (raises ``csv.Error``)."""
    names = [h.strip() for h in next(reader, [])]
    if "input" not in names:
        raise InputError("a CSV manifest starts with a header row naming an 'input' column", path=path, line=1)
    rows = []
    for cells in reader:
        if not any(c.strip() for c in cells):
            continue
        if len(cells) != len(names):
            raise InputError(f"{len(cells)} cells but the header names {len(names)} columns", path=path, line=reader.line_num)
        rows.append((reader.line_num, {k: v.strip() for k, v in zip(names, cells) if v.strip()}))
    return rows


def _jsonl_rows(text: str, path: Path) -> list[tuple[int, dict[str, Any]]]:
    """``(line, object)`` per non-blank, non-comment line; ``null`` values left out."""
    rows = []
    for n, ln in enumerate(text.splitlines(), start=1):
        if not ln.strip() or ln.lstrip().startswith("#"):
            continue
        try:
            row = json.loads(ln)
        except ValueError as exc:
            raise InputError(f"not a JSON object: {exc}", path=path, line=n) from None
        if not isinstance(row, dict):
            raise InputError(f"expected a JSON object, found {type(row).__name__}", path=path, line=n)
        rows.append((n, {k: v for k, v in row.items() if v is not None}))
    return rows


def _entry(line: int, row: dict[str, Any], manifest: Path, table: "OptionTable") -> ManifestEntry:
    """One manifest row as an entry: paths resolved against the manifest's folder, options
    parsed and checked as ``retarget`` does (:func:`parse_file_options`)."""
    base = manifest.parent
    row = dict(row)
    inp, out = row.pop("input", None), row.pop("output", None)
    for key, value in (("input", inp), ("output", out)):
        if value is not None and (not isinstance(value, str) or not value.strip()):
            raise InputError(f"{key} must be a path, got {value!r}", path=manifest, line=line)
    if inp is None:
        raise InputError("no input on this line", path=manifest, line=line)
    if out is not None and out.endswith(("/", os.sep)):  # base / out would drop the separator
        raise OptionError(f"output {out!r} ends with a path separator, which names a directory; expected a file name",
                          path=manifest, line=line)
    output = None if out is None else base / out
    if output is not None and output.suffix.lower() not in OUTPUT_SUFFIXES:
        raise OptionError(f"output {out!r}: the suffix must be one of {', '.join(OUTPUT_SUFFIXES)}",
                          path=manifest, line=line)
    try:
        options = parse_file_options(row, table, base)
    except OptionError as exc:
        raise OptionError(exc.message, path=manifest, line=line) from None
    return ManifestEntry(line, base / inp, output, options)


class _TableParser(argparse.ArgumentParser):
    """An argument parser that keeps every action ``add_argument`` returns (in
    :attr:`actions`) and raises :class:`OptionError` instead of exiting."""

    def __init__(self) -> None:
        self.actions: list[argparse.Action] = []  # first: argparse's own __init__ may add arguments
        super().__init__(prog="retarget", add_help=False)

    def add_argument(self, *args: Any, **kwargs: Any) -> argparse.Action:
        action = super().add_argument(*args, **kwargs)
        self.actions.append(action)
        return action

    def error(self, message: str):  # type: ignore[override]
        raise OptionError(message)


@dataclass(frozen=True)
class OptionTable:
    """``retarget``'s per-file options: the parser that reads their values and, by argparse
    destination, the action each ``add_argument`` call returned (:meth:`build`)."""

    parser: argparse.ArgumentParser
    actions: dict[str, argparse.Action]

    @classmethod
    def build(cls) -> "OptionTable":
        """The table built by the functions that declare ``retarget``'s options
        (:func:`~physmocap.cli.retarget.add_retarget_options`,
        :func:`~physmocap.cli.retarget.add_bvh_output_options`); ``--quiet`` is not per file."""
        from .cli.retarget import add_bvh_output_options, add_retarget_options

        parser = _TableParser()
        add_retarget_options(parser)
        add_bvh_output_options(parser)
        return cls(parser, {a.dest: a for a in parser.actions if a.option_strings and a.dest != "quiet"})

    def lookup(self, key: Any) -> argparse.Action:
        """The action of a manifest's option name (``no-plant``, ``--no-plant``, ``no_plant``).

        Raises:
            OptionError: Not a per-file option.
        """
        action = self.actions.get(str(key).strip().lstrip("-").replace("-", "_"))
        if action is None:
            known = ", ".join(sorted(a.option_strings[-1].lstrip("-") for a in self.actions.values()))
            raise OptionError(f"unknown option {key!r}; per-file options are input, output and {known}")
        return action


def parse_file_options(row: dict[str, Any], table: OptionTable, base: Path) -> dict[str, Any]:
    """Per-file options (``retarget``'s option names) parsed by ``table`` and validated by
    :func:`~physmocap.cli.retarget.config_from_args`, the configuration ``retarget`` builds:
    argparse destination -> value, only the options given.  The paths of
    :data:`PATH_OPTIONS` are taken relative to ``base``.

    Raises:
        OptionError: An unknown option, one that is not per-file, or a bad value.
    """
    from .cli.retarget import config_from_args

    given: dict[str, Any] = {}
    for key, value in row.items():
        action = table.lookup(key)
        given[action.dest] = _parse_value(action, value, table.parser)
    for dest in PATH_OPTIONS:
        if isinstance(given.get(dest), str) and (dest != "character" or _is_path(given[dest])):
            given[dest] = str(base / given[dest])
    full = table.parser.parse_args([])
    vars(full).update(given)
    config_from_args(full)  # the checks retarget makes before reading anything
    return given


def _parse_value(action: argparse.Action, value: Any, parser: argparse.ArgumentParser) -> Any:
    """A manifest cell or JSON value for one option, parsed as the command line would."""
    name = action.option_strings[-1]
    if action.nargs == 0:  # a flag (store_true)
        text = str(value).strip().lower() if not isinstance(value, bool) else str(value).lower()
        flag = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}.get(text)
        if flag is None:
            raise OptionError(f"{name} is a flag: give true or false, got {value!r}")
        return flag
    if isinstance(value, (dict, list, bool)):
        raise OptionError(f"{name} takes one value, got {value!r}")
    return getattr(parser.parse_args([f"{name}={value}"]), action.dest)  # "=": a value may start with "-"


def _is_path(value: str) -> bool:
    """True for a character given as a file (a suffix or a folder), not a bundled name."""
    return bool(Path(value).suffix) or "/" in value or os.sep in value


def plan(source: str, outdir: str | os.PathLike, suffix: str = ".npz", options: dict[str, Any] | None = None) -> list[Job]:
    """The jobs for every input of ``source``: outputs mirrored under ``outdir`` unless a
    manifest names them, with the manifest's per-file options.  A manifest line's own
    ``character`` or ``map`` is loaded here (with the batch's ``options`` for the one it does
    not give), once per pair.

    Raises:
        InputError: No input found, or a manifest that cannot be read.
        OptionError: A manifest's bad option, or two jobs writing the same output.
        PhysmocapError: A manifest line's character cannot be loaded (naming the line).
    """
    entries, root = _inputs(source, Path(outdir))
    if not entries:
        raise InputError("no input files found (looked for " + ", ".join(INPUT_SUFFIXES) + ")", path=source)
    jobs: list[Job] = []
    seen: dict[str, tuple[int, Path]] = {}  # output -> the manifest line and input that write it
    folders: set[Path] = set()
    characters = _CharacterCheck(options or {})
    for e in entries:
        if e.line:
            _check_entry(e, source, folders)
            characters.check(e, source)
        target = e.output.resolve() if e.output is not None else _mirrored(e.input, root, Path(outdir), suffix)
        if target == e.input.resolve():
            raise OptionError(f"the output {target} is the input itself", path=source, line=e.line or None)
        if str(target) in seen:
            line, first = seen[str(target)]
            where = f"lines {line} and {e.line}" if e.line else f"{first} and {e.input}"
            shown = os.path.relpath(target) if not os.path.isabs(outdir) else target
            raise OptionError(f"{where} would write the same output {shown}; give one of them its own output "
                              "in a manifest (CSV or JSON lines: input, output)", path=source)
        seen[str(target)] = (e.line, e.input)
        # the input as given (absolute, links kept): its path in the summary is the one the user wrote
        jobs.append(Job(input=os.path.abspath(e.input), output=str(target), options=dict(e.options)))
    return jobs


def _check_entry(entry: ManifestEntry, manifest: str, folders: set[Path]) -> None:
    """A manifest line's input must exist and its own output must be writable (the nearest
    existing folder of it accepts a file; ``folders``: those already checked).

    Raises:
        InputError: The input is missing.  OutputError: The output cannot be written.
    """
    if not entry.input.is_file():
        raise InputError(f"input {str(entry.input)!r} not found", path=manifest, line=entry.line)
    if entry.output is None:
        return
    folder = entry.output.resolve().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if folder not in folders:
        try:
            check_output_dir(folder, "output's folder")
        except OutputError as exc:
            raise OutputError(f"output {str(entry.output)!r}: {exc}", path=manifest, line=entry.line) from None
        folders.add(folder)


class _CharacterCheck:
    """Loads the character a manifest line asks for (its ``character`` and ``map``, the
    batch's for the one it does not give), each pair once, so that a name that is not
    bundled or a file that cannot be loaded is an error naming the line before any file runs."""

    def __init__(self, options: dict[str, Any]) -> None:
        self.options = options
        self.loaded: set[tuple[str | None, str | None]] = set()

    def check(self, entry: ManifestEntry, manifest: str) -> None:
        """Load the line's character unless it gives neither ``character`` nor ``map``.

        Raises:
            PhysmocapError: The character cannot be loaded (its own error, naming the line).
        """
        if "character" not in entry.options and "map" not in entry.options:
            return  # the batch's own character, checked once by the caller
        pair = tuple(entry.options.get(k, self.options.get(k)) for k in ("character", "map"))
        if pair in self.loaded:
            return
        from .models import load_character

        try:
            load_character(*pair)
        except PhysmocapError as exc:
            raise type(exc)(f"character: {exc}", path=manifest, line=entry.line) from None
        self.loaded.add(pair)


def _mirrored(inp: Path, root: Path, out: Path, suffix: str) -> Path:
    """``out/<inp relative to root>`` with ``suffix`` (absolute).  Paths are made absolute
    without following links: a folder of links to clips elsewhere mirrors the links' names."""
    f, r = Path(os.path.abspath(inp)), Path(os.path.abspath(root))
    rel = f.relative_to(r) if f.is_relative_to(r) else Path(f.name)
    return (out / rel).with_suffix(suffix).resolve()


def options_key(options: dict[str, Any]) -> str:
    """A stable digest of the retarget options (resuming redoes a file when they change)."""
    return hashlib.sha256(json.dumps(options, sort_keys=True).encode()).hexdigest()[:16]


def job_options(job: Job, options: dict[str, Any]) -> dict[str, Any]:
    """The batch's ``options`` with the job's own on top: what the file is retargeted with.
    The batch's marker options (``--marker-set``, ``--joint-centres``, the marker solve's:
    :data:`~physmocap.cli.retarget.MARKER_OPTIONS_UNSET`) apply to its marker files only, so
    a folder can mix them with skeleton files; a file's own are checked as given."""
    from .cli.retarget import MARKER_OPTIONS_UNSET
    from .sources.markers import is_marker_file

    try:
        markers = is_marker_file(job.input)
    except PhysmocapError:  # an .mcap that does not read: its own run fails and is recorded
        markers = False
    shared = options if markers else {**options, **MARKER_OPTIONS_UNSET}
    return {**shared, **job.options}


#: What a job's caller is told as its file is retargeted: ``(frames done, frames in all)``.
FrameCallback = Callable[[int, int], None]


def run_job(job: Job, options: dict[str, Any], on_frames: FrameCallback | None = None) -> FileResult:
    """Retarget one file with the ``retarget`` command's options (the batch's, the job's own
    on top); never raises.  ``on_frames(done, total)`` is called as the frames are retargeted.

    A failure's ``frame`` is the one its error names (a reader's: a source frame) or else, for
    a failure while retargeting, the frame being retargeted (0: the first one retargeted,
    after ``--start`` and ``--fps``)."""
    import warnings

    from .cli.retarget import retarget_from_args, write_outputs
    from .progress import observe

    start = time.perf_counter()
    res = FileResult(job.input, job.output, "failed")
    solving = _SolveTracker(on_frames)
    try:
        ns = argparse.Namespace(**{**job_options(job, options), "input": job.input, "quiet": True})
        with warnings.catch_warnings(), observe(solving):
            warnings.simplefilter("ignore")
            traj = retarget_from_args(ns)
            Path(job.output).parent.mkdir(parents=True, exist_ok=True)  # once there is a result to write
            write_outputs(traj, [Path(job.output)], ns, quiet=True)
        _measure(traj, res)
        res.status = "done"  # only once every figure is measured: a failing metric fails the file
    except PhysmocapError as exc:
        res.error, res.frame = str(exc), exc.frame if exc.frame is not None else solving.frame
    except Exception as exc:  # noqa: BLE001 - one file's failure must not stop the dataset
        res.error, res.frame = f"{type(exc).__name__}: {exc}".splitlines()[0][:300], solving.frame
    res.seconds = time.perf_counter() - start
    return res


class _SolveTracker:
    """A :func:`~physmocap.progress.observe` callback following the ``retarget`` bar: passes
    its counts on, and knows the frame being retargeted (None before or after the solve)."""

    def __init__(self, on_frames: FrameCallback | None) -> None:
        self.on_frames = on_frames
        self.done, self.total = 0, 0

    def __call__(self, bar: Any) -> None:
        if bar.label != "retarget":
            return
        self.done, self.total = bar.done, bar.total
        if self.on_frames is not None:
            self.on_frames(bar.done, bar.total)

    @property
    def frame(self) -> int | None:
        return _solving_frame(self.done, self.total)


def _solving_frame(done: int, total: int) -> int | None:
    """The frame being retargeted after ``done`` of ``total`` (None when not retargeting)."""
    return done if 0 <= done < total else None


def _measure(traj: Any, res: FileResult) -> None:
    """Fill ``res``'s frame count and quality figures from the trajectory."""
    from . import metrics

    ch = traj.character
    fid = traj.fidelity
    res.frames, res.fps = int(traj.num_frames), round(float(traj.fps), 4)  # a BVH frame time of 0.008333 s: 120.0048
    res.limit_violations = int(metrics.joint_limit_violations(ch.model, traj.qpos)["count"])
    res.penetration_max_mm = _figure(metrics.penetration(ch.model, traj.qpos)["max_mm"], 3)
    if traj.contacts is not None:
        res.skating_mean_cm_s = _figure(metrics.character_skating(traj)["mean_cm_s"], 3)
    if fid is not None:
        res.worst_segment_median_deg = _figure(fid.worst_segment_median_deg, 2)
        res.facing_p95_deg = _figure(fid.facing_p95_deg, 2)
        res.path_mean_cm = _figure(fid.path_mean_cm, 2)
        res.saturated_share = _figure(fid.saturated_share, 4)
        if fid.pops is not None:
            res.pop_frames = int(fid.pops.frames.size)
            res.largest_pop_cm = _figure(fid.pops.worst_cm, 2)


def _figure(value: Any, digits: int) -> float | None:
    """A quality figure rounded for the summary; None when not measured or not finite (a
    NaN or infinity never reaches summary.json, which is strict JSON)."""
    if value is None:
        return None
    v = float(value)
    return round(v, digits) if math.isfinite(v) else None


def _load_state(outdir: Path) -> dict[str, dict]:
    """Output -> {"key": options digest, "result": its FileResult} of the files done before."""
    try:
        data = json.loads((outdir / STATE_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict):
        return {}
    return {str(k): v for k, v in data.items() if isinstance(v, dict) and isinstance(v.get("result"), dict)}


def _done(job: Job, key: str, state: dict[str, dict]) -> bool:
    out, inp = Path(job.output), Path(job.input)
    entry = state.get(job.output)
    return (
        entry is not None
        and entry.get("key") == key
        and out.exists()
        and inp.exists()
        and out.stat().st_mtime >= inp.stat().st_mtime
    )


def _death(exitcode: int | None) -> str:
    """The error of a job whose worker process died (a negative exit code is a signal)."""
    if exitcode is None:
        return "worker process died (exit code unknown)"
    if exitcode < 0:
        try:
            name = f", {signal.Signals(-exitcode).name}"
        except ValueError:
            name = ""
        return f"worker process died (signal {-exitcode}{name})"
    return f"worker process died (exit code {exitcode})"


def _worker_loop(conn: Connection, func: Callable[..., FileResult]) -> None:
    """A pool process: for each ``(job, options)`` received, say ``("started",)``, run
    ``func(job, options, on_frames)``, sending ``("frames", done, total)`` as it goes and
    ``("result", FileResult)`` at the end; stops on None or when the batch has gone.  Ctrl-C
    is the batch's to handle."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        job, options = task
        conn.send(("started",))
        result = func(job, options, lambda done, total: conn.send(("frames", done, total)))
        conn.send(("result", result))


@dataclass
class _Worker:
    """A pool process, the parent's end of its pipe, the job it was given (None: idle),
    whether it has started it, and the frames of it retargeted so far."""

    process: Any
    conn: Connection
    job: Job | None = None
    started: bool = False
    done: int = 0
    total: int = 0


class _Pool:
    """``workers`` processes (``spawn``), each running one job at a time.  A process that
    dies fails its own job (:func:`_death`, with the frame it had reached) and is replaced;
    the other jobs go on.  One that dies before starting the job it was given (killed while
    idle) hands it on to the next process, once."""

    def __init__(self, workers: int, func: Callable[..., FileResult], options: dict[str, Any],
                 on_frames: Callable[[int], None]) -> None:
        import multiprocessing

        self.context = multiprocessing.get_context("spawn")
        self.workers, self.func, self.options, self.on_frames = workers, func, options, on_frames
        self.pool: list[_Worker] = []
        self.handed_on: set[Job] = set()

    def run(self, jobs: list[Job]) -> Iterator[FileResult]:
        """The jobs' results as they complete; every process is gone when this ends."""
        queue = list(reversed(jobs))
        try:
            for _ in range(min(self.workers, len(jobs))):
                self._assign(self._start(), queue)
            while self.pool:
                yield from self._step(queue)
        finally:
            self._stop()

    def _start(self) -> _Worker:
        parent, child = self.context.Pipe()
        process = self.context.Process(target=_worker_loop, args=(child, self.func), daemon=True)
        process.start()
        child.close()  # the parent sees EOF once the process is gone
        worker = _Worker(process, parent)
        self.pool.append(worker)
        return worker

    def _assign(self, worker: _Worker, queue: list[Job]) -> None:
        """Give ``worker`` the next job, or let it go when none is left."""
        if not queue:
            self._retire(worker)
            return
        job = queue.pop()
        try:
            worker.conn.send((job, self.options))
        except OSError:  # gone since its last result: the job goes to a new process
            queue.append(job)
            self._discard(worker)
            self._assign(self._start(), queue)
            return
        worker.job, worker.started, worker.done, worker.total = job, False, 0, 0

    def _retire(self, worker: _Worker) -> None:
        with contextlib.suppress(OSError):
            worker.conn.send(None)
        worker.process.join(timeout=WORKER_EXIT_SECONDS)
        self._discard(worker)

    def _discard(self, worker: _Worker) -> None:
        if worker.process.is_alive():
            worker.process.terminate()
            worker.process.join()
        worker.conn.close()
        self.pool.remove(worker)

    def _step(self, queue: list[Job]) -> Iterator[FileResult]:
        """Wait for any worker's message or exit, and deal with it."""
        ready = set(wait([w.conn for w in self.pool] + [w.process.sentinel for w in self.pool]))
        for worker in list(self.pool):
            if worker.conn in ready or worker.process.sentinel in ready:
                yield from self._serve(worker, queue)

    def _serve(self, worker: _Worker, queue: list[Job]) -> Iterator[FileResult]:
        """Read what ``worker`` sent; a result frees it for the next job, an exit fails its job."""
        try:
            while worker.conn.poll():
                message = worker.conn.recv()
                if message[0] == "started":
                    worker.started = True
                elif message[0] == "frames":
                    self.on_frames(max(message[1] - worker.done, 0))
                    worker.done, worker.total = message[1], message[2]
                else:
                    worker.job = None
                    yield message[1]
                    self._assign(worker, queue)
                    return
            if worker.process.is_alive():
                return
        except (EOFError, OSError):  # the pipe closed: the process is gone or going
            worker.process.join(timeout=WORKER_EXIT_SECONDS)
        yield from self._replace(worker, queue)

    def _replace(self, worker: _Worker, queue: list[Job]) -> Iterator[FileResult]:
        """``worker`` died: fail its job (if it had one), and start another process if jobs remain."""
        job = worker.job
        self._discard(worker)
        if job is not None and not worker.started and job not in self.handed_on:
            self.handed_on.add(job)  # not this job's doing
            queue.append(job)
        elif job is not None:
            yield FileResult(job.input, job.output, "failed", error=_death(worker.process.exitcode),
                             frame=_solving_frame(worker.done, worker.total))
        if queue:
            self._assign(self._start(), queue)

    def _stop(self) -> None:
        """End every process still there (an interrupted batch: at once)."""
        for worker in list(self.pool):
            with contextlib.suppress(OSError):
                worker.conn.close()
            if worker.process.is_alive():
                worker.process.terminate()
            worker.process.join()
        self.pool.clear()


def _ray_connect(address: str) -> tuple[Any, bool]:
    """The ``ray`` module, connected to ``address`` ('local' starts Ray here, 'auto' joins
    the running cluster), and whether this call connected it (the caller shuts it down).
    HOST:PORT or ray://HOST:PORT (or the ``RAY_ADDRESS`` that 'auto' takes) is probed first,
    so that an address where nothing listens fails within :data:`RAY_CONNECT_SECONDS`
    instead of Ray's own minutes of retries.

    Raises:
        OptionError: Ray is missing, the address is malformed or unreachable, or Ray refuses it.
    """
    try:
        import ray
    except ImportError:
        raise OptionError("--ray needs Ray: pip install 'physmocap[cluster]'") from None
    if ray.is_initialized():
        return ray, False
    target = os.environ.get("RAY_ADDRESS", "") if address == "auto" else address  # what 'auto' joins first
    if target not in ("", "local", "auto"):
        _probe(target, f"--ray {address}" + (f" (RAY_ADDRESS={target})" if target != address else ""))
    try:
        ray.init(address=None if address == "local" else address, include_dashboard=False, log_to_driver=False)
    except Exception as exc:  # noqa: BLE001 - Ray raises ConnectionError, RuntimeError, ValueError...
        detail = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise OptionError(f"--ray {address}: cannot connect to Ray: {detail}") from None
    return ray, True


def _probe(address: str, option: str) -> None:
    """Check that something listens at a Ray address (HOST:PORT, ray://HOST:PORT); errors
    start with ``option`` (how the user gave it).

    Raises:
        OptionError: The address is malformed, nothing answers there within the timeout, or
            what answers does not speak gRPC (HTTP/2) as a Ray cluster does (skipped with
            ``RAY_USE_TLS``).
    """
    import socket

    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        raise OptionError(f"{option}: expected local, auto, HOST:PORT or ray://HOST:PORT")
    try:
        conn = socket.create_connection((host.strip("[]"), int(port)), timeout=RAY_CONNECT_SECONDS)
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise OptionError(f"{option}: no Ray cluster answers there ({reason}); start one with "
                          "'ray start --head' or give the address it prints") from None
    with conn:
        if os.environ.get("RAY_USE_TLS", "0").lower() in ("1", "true"):
            return  # gRPC over TLS: the plain handshake below does not apply
        # Ray's cluster (and client) servers speak gRPC, HTTP/2: to the client's connection
        # preface and an empty SETTINGS frame they answer with a SETTINGS frame (type 4, the
        # fourth byte of a frame header).  Anything else listening there (a web server) would
        # leave ray.init retrying for minutes.
        try:
            conn.sendall(HTTP2_PREFACE)
            head = b""
            while len(head) < 4:
                chunk = conn.recv(4 - len(head))
                if not chunk:
                    break
                head += chunk
        except OSError:
            head = b""
        if len(head) < 4 or head[3] != 4:
            raise OptionError(f"{option}: something listens there but it does not answer as a Ray cluster "
                              "does (gRPC); give the address 'ray start --head' prints") from None


def _ray_results(jobs: list[Job], options: dict[str, Any], ray: Any, func: Callable[..., FileResult]) -> Iterator[FileResult]:
    """The jobs' results as Ray tasks complete (no retry: a file whose worker dies fails, as
    on the local pool; re-running the batch retries it)."""
    task = ray.remote(max_retries=0)(func)
    pending = {task.remote(j, options): j for j in jobs}
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        job = pending.pop(ready[0])
        try:
            yield ray.get(ready[0])
        except ray.exceptions.RayError as exc:
            yield FileResult(job.input, job.output, "failed", error=_ray_failure(ray, exc))


def _ray_failure(ray: Any, exc: Exception) -> str:
    """The error of a Ray task that returned no result."""
    died = (ray.exceptions.WorkerCrashedError, ray.exceptions.OutOfMemoryError, ray.exceptions.NodeDiedError)
    first = (str(exc).strip().splitlines() or [""])[0][:200]
    if isinstance(exc, died):
        return f"worker process died (Ray {type(exc).__name__}: {first})"
    return f"Ray {type(exc).__name__}: {first}"


def _execute(jobs: list[Job], options: dict[str, Any], workers: int, ray: Any,
             on_frames: Callable[[int], None]) -> Iterator[FileResult]:
    """Results as they complete: in this process (one worker), on a :class:`_Pool`, or as
    Ray tasks (``ray``: the connected module); ``on_frames(n)``: n more frames retargeted
    (Ray: a file's frames once it is done)."""
    if ray is not None:
        for res in _ray_results(jobs, options, ray, run_job):
            on_frames(res.frames)
            yield res
    elif workers <= 1:
        for j in jobs:
            counter = _FrameCounter(on_frames)
            yield run_job(j, options, counter)
    else:
        yield from _Pool(workers, run_job, options, on_frames).run(jobs)


class _FrameCounter:
    """An ``on_frames(done, total)`` callback that passes on the frames added since its last call."""

    def __init__(self, on_frames: Callable[[int], None]) -> None:
        self.on_frames, self.done = on_frames, 0

    def __call__(self, done: int, total: int) -> None:
        self.on_frames(max(done - self.done, 0))
        self.done = done


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
    """Run the jobs, skip those already done (same output, newer than the input, same options
    with the job's own), write the summaries; results sorted by input, then output.

    With ``ray`` (an address: see :func:`_ray_connect`) the jobs are Ray tasks; otherwise
    ``workers`` processes (:class:`_Pool`; one: this process).  A file whose process dies
    is a failure like any other.

    Raises:
        OptionError: Ray is wanted but cannot be reached.
    """
    from .progress import Progress

    out = Path(outdir)
    if out.exists() and not out.is_dir():
        raise OutputError("is a file: the outputs need a folder (OUTDIR)", path=out)
    keys = {j.output: options_key(job_options(j, options)) for j in jobs}
    state = {} if force else _load_state(out)
    todo = [j for j in jobs if force or not _done(j, keys[j.output], state)]
    # files done by an earlier run keep their figures (the summary is the same either way)
    results = {}
    for j in jobs:
        if j not in todo:
            kept = {k: v for k, v in state[j.output]["result"].items() if k in FileResult.__dataclass_fields__}
            results[j.output] = FileResult(**{**kept, "seconds": 0.0})
    ray_mod, connected = _ray_connect(ray) if ray is not None and todo else (None, False)
    try:
        try:  # after Ray: a batch that cannot start leaves no folder
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"cannot create the output folder: {exc.strerror or exc}", path=out) from None
        with Progress(len(todo), "batch", enabled=progress, unit="files", tally="frames") as bar:
            _run(todo, options, workers, ray_mod, bar, state, keys, results, out)
    finally:
        if connected:
            ray_mod.shutdown()
    ordered = [results[j.output] for j in sorted(jobs, key=lambda j: (j.input, j.output))]
    _write_summaries(ordered, out)
    return ordered


def _run(todo: list[Job], options: dict[str, Any], workers: int, ray: Any, bar: Any, state: dict[str, dict],
         keys: dict[str, str], results: dict[str, FileResult], out: Path) -> None:
    """Run the jobs, keeping ``results`` and the resumable state up to date after every file."""
    from .fileio import atomic_open

    for res in _execute(todo, options, workers, ray, lambda n: bar.update(0, tally=n)):
        results[res.output] = res
        if res.status == "done":
            state[res.output] = {"key": keys[res.output], "result": asdict(res)}
        else:
            state.pop(res.output, None)
        with atomic_open(out / STATE_FILE) as fh:  # after every file: a killed batch resumes
            json.dump(state, fh, sort_keys=True, indent=0)
        bar.update(1)


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
        if row.get("error"):  # an error names its file as the reader had it: the same relative path
            row["error"] = row["error"].replace(r.input, row["input"])
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
