"""Atomic output files: write to a temporary file beside the target, then rename.

A failed or interrupted write never leaves a half-written output file, and an
existing file at the target path is only replaced once the new one is complete.
A run that writes several files does so inside an :class:`OutputSet`: every
file is written to its temporary sibling first and all are renamed together at
the end, so a failure in any of them leaves none of the run's new files.
Also here: the checks of output paths made before any work, and bounded
readers of untrusted text, JSON, TOML and NPZ.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import os
import tempfile
from pathlib import Path
from typing import IO, Iterator

from .errors import OptionError, OutputError


def _check_folder(folder: Path, target: Path, what: str) -> None:
    """``folder`` must be an existing directory in which a file can be made; else an
    :class:`OutputError` about ``target`` saying which part is wrong."""
    probe = folder
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise OutputError(f"{str(probe)!r} is a file, not a directory; the {what} cannot be created", path=target)
    if probe != folder:
        raise OutputError(f"directory {str(folder)!r} does not exist; the {what} cannot be created", path=target)
    try:  # os.access says yes to root on read-only mounts and /proc: try it
        fd, tmp = tempfile.mkstemp(prefix=".physmocap-probe.", dir=folder)
    except OSError as exc:
        raise OutputError(f"the {what} cannot be created in {str(folder)!r}: {exc.strerror or exc}", path=target) from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(tmp)


def check_writable(path: str | os.PathLike, what: str = "output file") -> Path:
    """Fail early, with a clear error, if ``path`` cannot be written: it is a directory,
    a part of its folder is a file, its folder does not exist, or no file can be
    created there (permissions, read-only or virtual file systems such as ``/proc``).
    Give the path as typed: ``Path`` drops the trailing separator of ``out.bvh/``, which
    names a directory, not a file.  An existing device or pipe is refused too (the new file
    would be renamed over it)."""
    raw = os.fspath(path)
    p = Path(path)
    if isinstance(raw, str) and raw.endswith(("/", os.sep)):
        raise OutputError(f"ends with a path separator, which names a directory; expected a file name for the {what}",
                          path=raw)
    if p.is_dir():
        raise OutputError(f"is a directory, expected a file name for the {what}", path=p)
    if p.exists() and not p.is_file():
        raise OutputError(f"is not a regular file (a device or a pipe); expected a file name for the {what}", path=p)
    _check_folder(p.parent if str(p.parent) else Path("."), p, what)
    return p


def suffix_error(path: str | os.PathLike, suffixes, what: str = "files") -> OptionError:
    """The error for an output whose suffix is not one of ``suffixes`` (``.bvh``...):
    ``out.xyz: cannot write .xyz files; use .bvh, .csv, .mcap or .npz`` (or ``no file
    suffix; use ...``)."""
    names = sorted(suffixes)
    choices = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " or " + names[-1]
    suffix = Path(path).suffix
    head = f"cannot write {suffix} {what}" if suffix else "no file suffix"
    return OptionError(f"{head}; use {choices}", path=path)


def check_readable(path: str | os.PathLike, kind: str) -> Path:
    """Fail early, with the reader's own error, if the input ``path`` (a ``kind`` such as
    ``"mapping file"``) does not exist, is a directory or cannot be opened; nothing is read.
    Pipes and devices are only required to exist (opening one could block)."""
    import stat

    from .errors import InputError

    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise InputError(f"{kind} not found", path=p) from None
    except OSError as exc:
        raise InputError(f"cannot read the {kind}: {exc.strerror or exc}", path=p) from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"is a directory, expected a {kind}", path=p)
    if stat.S_ISREG(st.st_mode):
        try:
            with open(p, "rb"):
                pass
        except OSError as exc:
            raise InputError(f"cannot read the {kind}: {exc.strerror or exc}", path=p) from None
    return p


def check_output_dir(path: str | os.PathLike, what: str = "output directory") -> Path:
    """Fail early if ``path`` is not a directory files can be written into, nor one that
    can be created (its parent must exist: only the last level is made)."""
    p = Path(path)
    if p.exists():
        if not p.is_dir():
            raise OutputError(f"is a file; the {what} must be a directory", path=p)
        _check_folder(p, p, what)
        return p
    parent = p.parent if str(p.parent) else Path(".")
    _check_folder(parent, p, what)
    try:  # a directory can be made where a file can, except on odd file systems: try it
        tmp = tempfile.mkdtemp(prefix=".physmocap-probe.", dir=parent)
    except OSError as exc:
        raise OutputError(f"the {what} cannot be created: {exc.strerror or exc}", path=p) from None
    with contextlib.suppress(OSError):
        os.rmdir(tmp)
    return p


def make_output_dir(path: str | os.PathLike, what: str = "output directory") -> Path:
    """Create ``path`` (not its parents) if missing, after :func:`check_output_dir`; a
    directory created inside an :class:`OutputSet` is removed again if the set fails."""
    p = check_output_dir(path, what)
    if not p.exists():
        try:
            p.mkdir()
        except FileExistsError:
            pass
        except OSError as exc:
            raise OutputError(f"the {what} cannot be created: {exc.strerror or exc}", path=p) from None
        else:
            current = _OUTPUT_SET.get()
            if current is not None:
                current._dirs.append(p)
    return p


def check_distinct(outputs) -> None:
    """Refuse two outputs of one run at the same path (the second would replace the first)."""
    seen: dict[Path, str] = {}
    for out in outputs:
        if out is None:
            continue
        key = Path(out).resolve()
        if key in seen:
            raise OutputError(f"given twice as an output (also as {seen[key]!r}); choose distinct paths", path=out)
        seen[key] = str(out)


def check_not_input(outputs, inputs) -> None:
    """Refuse an output path that is one of the inputs (a run must never overwrite its capture)."""
    ins = [Path(i) for i in inputs if i is not None]
    for out in outputs:
        if out is None:
            continue
        o = Path(out)
        for i in ins:
            same = o.resolve() == i.resolve()
            if not same and o.exists() and i.exists():
                same = os.path.samefile(o, i)
            if same:
                raise OutputError("the output is the input file: choose another output path", path=o)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, keep_suffix: bool = True) -> Iterator[Path]:
    """A temporary file beside ``path`` (with the same suffix, for writers that pick a
    format from the name, such as video encoders), renamed over ``path`` when the
    ``with`` block succeeds and removed on any exception, leaving ``path`` untouched."""
    p = check_writable(path)
    suffix = f".tmp{p.suffix}" if keep_suffix else ".tmp"
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=suffix, dir=p.parent or ".")
    except OSError as exc:
        raise OutputError(f"cannot create a file here: {exc.strerror}", path=p) from None
    os.close(fd)
    current = _OUTPUT_SET.get()
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)
        if current is None:
            os.replace(tmp, p)
        else:
            current._add(Path(tmp), p)
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if not _is_write_error(exc, tmp, p):
            raise
        raise write_error(exc, p) from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


#: What an errno of a failed write means for the user, beyond its ``strerror``.
_WRITE_HINTS = {errno.EFBIG: "beyond the size limit for one file: ulimit -f, or the file system's"}


def _is_write_error(exc: OSError, tmp: str | os.PathLike, target: Path) -> bool:
    """True when ``exc``, raised while writing ``tmp`` for ``target``, is about that file (it
    names no other file): a full disk, a size limit, an I/O error..."""
    if exc.errno is None or isinstance(exc, BrokenPipeError):
        return False
    return exc.filename is None or os.fspath(exc.filename) in (os.fspath(tmp), os.fspath(target))


def write_error(exc: OSError, target: str | os.PathLike) -> OutputError:
    """An :class:`OutputError` naming ``target`` (the final output, never its temporary
    sibling) for the OSError ``exc`` raised while writing it (EFBIG, ENOSPC, EIO...)."""
    reason = (exc.strerror or os.strerror(exc.errno)) if exc.errno else str(exc)
    hint = _WRITE_HINTS.get(exc.errno)
    detail = f"{reason} ({hint})" if hint else reason
    return OutputError(f"not written: {detail}", path=target)


#: The :class:`OutputSet` collecting the current run's outputs, if any.
_OUTPUT_SET: contextvars.ContextVar["OutputSet | None"] = contextvars.ContextVar("physmocap_output_set", default=None)


class OutputSet:
    """All the outputs of one run, renamed into place together once every one is written.

    Inside ``with OutputSet():`` every :func:`atomic_path` / :func:`atomic_open` (so every
    physmocap writer) leaves its finished temporary file beside its target instead of
    renaming it; when the block ends without an exception, all of them are renamed (one
    ``os.replace`` each, back to back), and :func:`announce` messages are printed.  On an
    exception, every temporary file and every directory made by :func:`make_output_dir` is
    removed, so a failed run leaves none of its new files and the old ones untouched.
    Sets nest: an inner set hands its files to the outer one.
    """

    def __init__(self) -> None:
        self._pending: list[tuple[Path, Path]] = []
        self._dirs: list[Path] = []
        self._messages: list[str] = []
        self._token = None
        self._outer: OutputSet | None = None

    def _add(self, tmp: Path, target: Path) -> None:
        key = target.resolve()
        for k, (old_tmp, old_target) in enumerate(self._pending):
            if old_target.resolve() == key:  # written twice in one run: the last one wins
                with contextlib.suppress(OSError):
                    os.unlink(old_tmp)
                del self._pending[k]
                break
        self._pending.append((tmp, target))

    @property
    def pending(self) -> list[Path]:
        """The targets waiting to be renamed into place."""
        return [t for _, t in self._pending]

    def __enter__(self) -> "OutputSet":
        self._outer = _OUTPUT_SET.get()
        self._token = _OUTPUT_SET.set(self)
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        _OUTPUT_SET.reset(self._token)
        if exc_type is not None:
            self.discard()
            return False
        if self._outer is not None:
            self._outer._pending.extend(self._pending)
            self._outer._dirs.extend(self._dirs)
            self._outer._messages.extend(self._messages)
            return False
        self.commit()
        return False

    def commit(self) -> None:
        import sys

        try:
            for k, (tmp, target) in enumerate(self._pending):
                os.replace(tmp, target)
        except BaseException as exc:
            failed_tmp, failed = self._pending[k]
            for tmp, _ in self._pending[k:]:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
            if isinstance(exc, OSError) and _is_write_error(exc, failed_tmp, failed):
                raise write_error(exc, failed) from None
            raise
        self._pending = []
        for m in self._messages:
            print(m, file=sys.stderr)
        self._messages = []

    def discard(self) -> None:
        for tmp, _ in self._pending:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        self._pending = []
        for d in reversed(self._dirs):
            with contextlib.suppress(OSError):
                os.rmdir(d)  # only if still empty: files put there by others stay
        self._dirs = []
        self._messages = []


def announce(message: str) -> None:
    """Print ``message`` (``wrote PATH``) on stderr now, or, inside an :class:`OutputSet`,
    once its files are in place (never for files a failed run did not keep)."""
    current = _OUTPUT_SET.get()
    if current is None:
        import sys

        print(message, file=sys.stderr)
    else:
        current._messages.append(message)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", **kwargs) -> Iterator[IO]:
    """Open a temporary file for writing; rename it over ``path`` on success.

    ``mode`` is ``"w"`` (text, UTF-8, ``\\n`` newlines unless ``newline`` given)
    or ``"wb"``.  On any exception the temporary file is removed and ``path``
    is left untouched (:func:`atomic_path`).
    """
    if mode not in ("w", "wb"):
        raise ValueError("atomic_open supports modes 'w' and 'wb'")
    if mode == "w":
        kwargs.setdefault("encoding", "utf-8")
        kwargs.setdefault("newline", "\n")
    with atomic_path(path, keep_suffix=False) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh


#: Largest mapping / marker-set file read (bytes): real ones are a few kilobytes.
MAX_TEXT_BYTES = 1 << 20
#: Deepest nesting of lists / tables accepted in JSON and TOML inputs.
MAX_NESTING = 64


def read_text(path: str | os.PathLike, kind: str, limit: int = MAX_TEXT_BYTES) -> str:
    """A small UTF-8 text file (mapping, marker set...), reading at most ``limit`` bytes, so
    ``/dev/zero`` or a huge file is refused instead of filling memory.  Errors name the file
    (and the line of a byte that is not UTF-8)."""
    from .errors import InputError

    p = Path(path)
    try:
        with open(p, "rb") as fh:
            data = fh.read(limit + 1)
    except FileNotFoundError:
        raise InputError(f"{kind} not found", path=p) from None
    except IsADirectoryError:
        raise InputError(f"is a directory, expected a {kind}", path=p) from None
    except OSError as exc:
        raise InputError(f"cannot read {kind}: {exc.strerror or exc}", path=p) from None
    if len(data) > limit:
        raise InputError(f"{kind} is larger than {limit // 1024} KB; expected a small text file", path=p)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError(f"not UTF-8 text (byte 0x{data[exc.start]:02x})", path=p, line=line) from None


def nesting_depth(text: str | bytes, limit: int = MAX_NESTING) -> int:
    """An upper bound of the bracket nesting of a JSON / TOML text, stopping past ``limit``
    (brackets inside strings count too, so it never under-estimates)."""
    if isinstance(text, str):
        text = text.encode("utf-8", "surrogatepass")
    if text.count(b"[") + text.count(b"{") <= limit:
        return text.count(b"[") + text.count(b"{")
    import numpy as np

    b = np.frombuffer(text, dtype=np.uint8)
    step = (b == ord("[")).astype(np.int32) + (b == ord("{"))
    step -= (b == ord("]")).astype(np.int32) + (b == ord("}"))
    return int(np.cumsum(step).max(initial=0))


def _json_int(s: str):
    # integers too long for a float or int64 become floats (inf when out of range), which every
    # reader's finite-number check then names; Python ints would overflow later, far from the file
    return int(s) if len(s) <= 15 else float(s)


def _no_constant(name: str):
    raise ValueError(f"non-finite number {name} is not JSON")


def parse_json(text: str | bytes, nan_constants: bool = False):
    """``json.loads`` for untrusted input: nesting deeper than the parser's recursion limit
    refused, integers beyond 15 digits read as floats (infinite when out of range),
    ``NaN`` / ``Infinity`` refused (or read as NaN with ``nan_constants``).  Raises
    ``ValueError`` with a message fit for a user.  Values kept as they are (free-form
    metadata) should also pass :func:`json_depth` against :data:`MAX_NESTING`."""
    import json
    import math

    constant = (lambda c: math.nan) if nan_constants else _no_constant
    if isinstance(text, bytes):
        text = text.decode("utf-8")
    try:
        return json.loads(text, parse_int=_json_int, parse_constant=constant)
    except RecursionError:
        raise ValueError("lists or objects nested too deeply") from None


def json_depth(obj, limit: int = MAX_NESTING) -> int:
    """Nesting depth of parsed JSON (lists and objects), counting no further than ``limit + 1``."""
    depth, level = 0, [obj]
    while level and depth <= limit:
        nxt = []
        for o in level:
            if isinstance(o, dict):
                nxt.extend(o.values())
            elif isinstance(o, list):
                nxt.extend(o)
        if not nxt and not any(isinstance(o, (dict, list)) for o in level):
            break
        depth += 1
        level = nxt
    return depth


def _tame_ints(obj):
    """Integers beyond 2**53 (a float cannot hold them exactly; past 1e308 not at all) as
    floats, infinite when out of range, so the checks for finite numbers name them."""
    import math

    if isinstance(obj, dict):
        return {k: _tame_ints(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_tame_ints(v) for v in obj]
    if isinstance(obj, int) and not isinstance(obj, bool) and abs(obj) > 2**53:
        try:
            return float(obj)
        except OverflowError:
            return math.inf if obj > 0 else -math.inf
    return obj


def read_toml(path: str | os.PathLike, kind: str = "mapping file") -> tuple[dict, str]:
    """Read a TOML file: ``(data, text)``; clear :class:`InputError` naming the file and line.

    ``kind`` names the file in messages (``"mapping file"``...).  At most
    :data:`MAX_TEXT_BYTES` are read and :data:`MAX_NESTING` levels of nesting accepted.
    Uses the standard library's ``tomllib`` (Python 3.11+) or ``tomli`` on 3.10.
    """
    import re

    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]

    from .errors import InputError

    p = Path(path)
    text = read_text(p, kind)
    if nesting_depth(text) > MAX_NESTING:
        raise InputError(f"not a {kind}: lists or tables nested deeper than {MAX_NESTING} levels", path=p)
    try:
        return _tame_ints(tomllib.loads(text)), text
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"at line (\d+)", str(exc))
        raise InputError(f"not valid TOML: {exc}", path=p, line=int(m.group(1)) if m else None) from None
    except RecursionError:  # pragma: no cover - nesting_depth stops it first
        raise InputError(f"not a {kind}: nested too deeply", path=p) from None


#: Largest NPZ accepted, in bytes once unpacked (all members together).
MAX_NPZ_BYTES = 1 << 30
#: Most members (arrays) an NPZ may hold.
MAX_NPZ_MEMBERS = 256


def read_npz(path: str | os.PathLike, kind: str = "an NPZ archive") -> dict:
    """All ``.npy`` arrays of an NPZ archive, read without pickle and within bounds.

    The zip directory is checked before anything is unpacked: at most
    :data:`MAX_NPZ_MEMBERS` members and :data:`MAX_NPZ_BYTES` once uncompressed (so a zip
    bomb costs nothing), and each array's header must declare exactly the bytes its member
    holds (so a header cannot make numpy allocate more than the file contains).  Raises
    :class:`InputError` naming the file and the array.
    """
    import zipfile

    import numpy as np
    from numpy.lib import format as npformat

    from .errors import InputError

    p = Path(path)
    try:
        with open(p, "rb") as fh:
            magic = fh.read(6)
    except FileNotFoundError:
        raise InputError("file not found", path=p) from None
    except IsADirectoryError:
        raise InputError(f"is a directory, expected {kind}", path=p) from None
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror or exc}", path=p) from None
    if magic == b"\x93NUMPY":
        raise InputError(f"a single .npy array, not an NPZ archive of named arrays; expected {kind}", path=p)
    if not magic:
        raise InputError(f"empty file; expected {kind}", path=p)
    try:
        zf = zipfile.ZipFile(p)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, ValueError, EOFError) as exc:
        raise InputError(f"not {kind} (not a zip archive: {exc})", path=p) from None
    out: dict[str, np.ndarray] = {}
    with zf:
        infos = [i for i in zf.infolist() if i.filename.endswith(".npy")]
        if len(infos) > MAX_NPZ_MEMBERS:
            raise InputError(f"{len(infos)} arrays; physmocap reads at most {MAX_NPZ_MEMBERS} from an NPZ", path=p)
        total = sum(i.file_size for i in infos)
        if total > MAX_NPZ_BYTES:
            raise InputError(
                f"its arrays would unpack to {total / 2**20:.0f} MB, more than the {MAX_NPZ_BYTES >> 20} MB "
                "physmocap reads from an NPZ",
                path=p,
            )
        for info in infos:
            key = info.filename[:-4]
            try:
                with zf.open(info) as fh:
                    version = npformat.read_magic(fh)
                    if version == (1, 0):
                        shape, fortran, dtype = npformat.read_array_header_1_0(fh)
                    elif version == (2, 0):
                        shape, fortran, dtype = npformat.read_array_header_2_0(fh)
                    else:
                        raise ValueError(f"unsupported .npy version {version}")
                    if dtype.hasobject:
                        raise InputError(
                            f"array {key!r} holds Python objects, which physmocap does not unpickle; "
                            "store strings as a string array (np.array(names, dtype=str))",
                            path=p,
                        )
                    count = 1
                    for n in shape:
                        count *= int(n)
                    need = count * dtype.itemsize
                    if need != info.file_size - fh.tell():
                        raise ValueError(f"its header declares shape {shape} ({need} bytes) but it holds "
                                         f"{info.file_size - fh.tell()} bytes")
                    arr = np.empty(count, dtype=dtype)
                    buf = memoryview(arr.view(np.uint8).reshape(-1)) if need else memoryview(b"")
                    got = 0
                    while got < need:
                        n = fh.readinto(buf[got:])
                        if not n:
                            raise ValueError("the member is truncated")
                        got += n
            except InputError:
                raise
            except Exception as exc:  # zipfile / npy header errors of many types
                detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                raise InputError(f"array {key!r} is not readable ({detail})", path=p) from None
            out[key] = arr.reshape(shape, order="F" if fortran else "C")
    return out


def npz_strings(arr, key: str, path: str | os.PathLike, count: int | None = None) -> list[str]:
    """A 1-D string array of an NPZ as ``str`` (bytes must be UTF-8); InputError otherwise."""
    import numpy as np

    from .errors import InputError

    arr = np.asarray(arr)
    want = f"({count},)" if count is not None else "1-D"
    if arr.ndim != 1 or arr.dtype.kind not in "US" or (count is not None and arr.shape != (count,)):
        raise InputError(f"'{key}' must be a {want} array of strings, got {arr.dtype} {arr.shape}", path=path)
    if arr.dtype.kind == "U":
        out = [str(x) for x in arr]
        for i, s in enumerate(out):  # a U array can hold lone surrogates: not text a file can name
            try:
                s.encode("utf-8")
            except UnicodeEncodeError:
                raise InputError(f"'{key}'[{i}] is not valid Unicode text", path=path) from None
        return out
    try:
        return [bytes(x).decode("utf-8") for x in arr]
    except UnicodeDecodeError:
        i = next(i for i, x in enumerate(arr) if not _utf8(bytes(x)))
        raise InputError(f"'{key}'[{i}] is not UTF-8 text ({bytes(arr[i])[:40]!r})", path=path) from None


def _utf8(b: bytes) -> bool:
    try:
        b.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def npz_text(arr, key: str, path: str | os.PathLike) -> str:
    """A scalar (0-d or one-element) string of an NPZ as ``str``; InputError otherwise."""
    import numpy as np

    from .errors import InputError

    arr = np.asarray(arr)
    if arr.size != 1 or arr.ndim > 1 or arr.dtype.kind not in "US":
        raise InputError(f"'{key}' must be a single string, got {arr.dtype} {arr.shape}", path=path)
    return npz_strings(arr.reshape(1), key, path)[0]


def npz_number(arr, key: str, path: str | os.PathLike, lo: float, hi: float, integer: bool = False) -> float:
    """A scalar (0-d or one-element) real number of an NPZ within ``[lo, hi]``; InputError
    otherwise (strings, NaN, booleans, arrays, out of range)."""
    import math

    import numpy as np

    from .errors import InputError

    arr = np.asarray(arr)
    kinds = "iu" if integer else "iuf"
    what = "an integer" if integer else "a number"
    if arr.size != 1 or arr.ndim > 1 or arr.dtype.kind not in kinds:
        raise InputError(f"'{key}' must be {what}, got {arr.dtype} {arr.shape}", path=path)
    v = arr.reshape(-1)[0]
    x = int(v) if integer else float(v)
    if not (math.isfinite(x) and lo <= x <= hi):
        raise InputError(f"'{key}' is {x!r}; expected {what} from {lo:g} to {hi:g}", path=path)
    return x


def npz_array(arr, key: str, path: str | os.PathLike, shape: tuple, kinds: str = "iuf"):
    """An NPZ array of real numbers (or ``kinds``) whose shape matches ``shape`` (a string
    such as ``"F"``: any length), as float (or as is for booleans); InputError naming the
    array otherwise."""
    import numpy as np

    from .errors import InputError

    arr = np.asarray(arr)
    ok = arr.ndim == len(shape) and all(isinstance(s, str) or s == n for s, n in zip(shape, arr.shape))
    if not ok or arr.dtype.kind not in kinds:
        want = "(" + ", ".join(str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        what = "booleans" if kinds == "b" else "numbers"
        raise InputError(f"'{key}' must be a {want} array of {what}, got {arr.dtype} {arr.shape}", path=path)
    return arr if kinds == "b" else arr.astype(float)
