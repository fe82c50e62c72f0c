"""User mapping files for source skeletons (TOML).

A mapping file names the source joint for canonical joints that a profile
gets wrong or does not know, optionally starting from a profile::

    # my_capture.map.toml
    profile = "cmu"              # optional: start from this profile ("topology", "none", ...)

    [joints]                     # canonical joint = source joint name
    left_wrist = "L_Wrist"
    right_wrist = "R_Wrist"
    neck = ["Neck1", "Neck"]     # a list: the first name the skeleton has
    head_end = false             # false: leave this joint untracked

Canonical joints may also be written at the top level, without ``[joints]``.
Names are matched exactly first, then after :func:`~.names.normalize_name`.
Every error names the file, the line of the entry and what is wrong.
"""

from __future__ import annotations

import difflib
import os
import re
from pathlib import Path
from typing import Any, Mapping

from ...canonical import CANONICAL_NAMES
from ...errors import MappingError
from ...fileio import read_toml

__all__ = ["load_mapping_file", "check_mapping", "UserMapping"]

#: What a checked mapping looks like: ``profile`` (str or None), ``joints``
#: (canonical -> tuple of candidate names, or None to leave it unmapped),
#: ``path`` (str or None) and ``lines`` (canonical -> 1-based line or None).
UserMapping = dict


def _line_of(text: str | None, key: str) -> int | None:
    if not text:
        return None
    pat = re.compile(rf'^\s*["\']?{re.escape(key)}["\']?\s*=')
    for n, line in enumerate(text.splitlines(), 1):
        if pat.match(line):
            return n
    return None


def _profiles() -> tuple[str, ...]:
    from .tables import profile_names

    return profile_names() + ("auto",)


def check_mapping(
    raw: Mapping[str, Any], path: str | os.PathLike | None = None, text: str | None = None
) -> UserMapping:
    """Check a mapping's structure and types (not yet against a skeleton).

    Args:
        raw: The parsed mapping (a TOML document or a dict written in code).
        path: Where it came from, for messages.
        text: The file's text, to report line numbers.

    Raises:
        MappingError: An entry is not a canonical joint, or its value is not a
            joint name, a list of names, or false; or the profile is unknown.
    """
    where = None if path is None else os.fspath(path)

    def fail(msg: str, key: str | None = None) -> MappingError:
        return MappingError(msg, path=where, line=_line_of(text, key) if key else None)

    if not isinstance(raw, Mapping):
        raise fail(f"a mapping must be a table of canonical joint = source joint name, got {raw!r}")
    profile = None
    entries: dict[str, Any] = {}
    for key, value in raw.items():
        if key == "profile":
            if not isinstance(value, str) or value not in _profiles():
                raise fail(
                    f"entry 'profile' = {value!r}: expected one of {', '.join(_profiles())}", key
                )
            profile = None if value == "auto" else value
        elif key == "joints":
            if not isinstance(value, Mapping):
                raise fail("[joints] must be a table of canonical joint = source joint name", key)
            for k, val in value.items():
                if k in entries:
                    raise fail(f"entry {k!r} is given twice (at the top level and in [joints])", k)
                entries[k] = val
        else:
            if key in entries:
                raise fail(f"entry {key!r} is given twice (at the top level and in [joints])", key)
            entries[key] = value
    joints: dict[str, tuple[str, ...] | None] = {}
    lines: dict[str, int | None] = {}
    for key, value in entries.items():
        if key not in CANONICAL_NAMES:
            close = difflib.get_close_matches(str(key), CANONICAL_NAMES, n=3)
            hint = f" (did you mean {' or '.join(close)}?)" if close else ""
            raise fail(
                f"entry {key!r} is not a canonical joint{hint}. Canonical joints: "
                + ", ".join(CANONICAL_NAMES),
                key,
            )
        if value is False:
            joints[key] = None
        elif isinstance(value, str) and value.strip():
            joints[key] = (value,)
        elif (
            isinstance(value, (list, tuple))
            and value
            and all(isinstance(v, str) and v.strip() for v in value)
        ):
            dup = next((v for i, v in enumerate(value) if v in value[:i]), None)
            if dup is not None:
                raise fail(f"entry {key!r} lists {dup!r} more than once", key)
            joints[key] = tuple(value)
        else:
            raise fail(
                f"entry {key!r} = {value!r}: expected a source joint name (a non-empty string), "
                "a list of names, or false to leave it unmapped",
                key,
            )
        lines[key] = _line_of(text, key)
    return {"profile": profile, "joints": joints, "path": where, "lines": lines}


def load_mapping_file(path: str | os.PathLike) -> UserMapping:
    """Read and check a mapping file (see the module docstring).

    Returns:
        ``{"profile": str | None, "joints": {canonical: (names...) | None},
        "path": str, "lines": {canonical: line}}``.

    Raises:
        InputError: The file is missing, unreadable or not valid TOML (the
            message gives the line).
        MappingError: An entry is wrong (the message names the entry and line).
    """
    p = Path(path)
    raw, text = read_toml(p, "mapping file")
    return check_mapping(raw, p, text)
