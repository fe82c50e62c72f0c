"""Errors and warnings that physmocap reports to users.

Every error a user can cause by giving bad input is a :class:`PhysmocapError`
whose message names the file, and where it applies the line or frame, and what
was expected.  The command-line interface prints such errors as one line on
stderr and exits with status 2; anything else is a bug in physmocap.
"""

from __future__ import annotations

import os
import sys
import warnings


class PhysmocapError(Exception):
    """A problem with the user's input, options or output path.

    Args:
        message: What is wrong and what was expected.
        path: The file concerned, if any.
        line: 1-based line number in that file, if known.
        frame: 0-based frame index, if the problem is tied to a frame.
    """

    def __init__(
        self,
        message: str,
        path: str | os.PathLike | None = None,
        line: int | None = None,
        frame: int | None = None,
    ) -> None:
        self.message = message
        self.path = None if path is None else os.fspath(path)
        self.line = line
        self.frame = frame
        super().__init__(self.__str__())

    def __str__(self) -> str:
        where = ""
        if self.path is not None:
            where = self.path
            if self.line is not None:
                where += f":{self.line}"
            where += ": "
        elif self.line is not None:
            where = f"line {self.line}: "
        if self.frame is not None:
            where += f"frame {self.frame}: "
        from .resources import display_text

        return display_text(where + self.message)  # the bundled clip as "example", not its installed path


class InputError(PhysmocapError):
    """An input file that cannot be read or is malformed."""


class MappingError(PhysmocapError):
    """A skeleton or character whose joints cannot be mapped as required."""


class OptionError(PhysmocapError):
    """An option value that is out of range or inconsistent."""


class OutputError(PhysmocapError):
    """An output path that cannot be written."""


class PhysmocapWarning(UserWarning):
    """Something was recovered from but the user should know (goes to stderr)."""


#: This package's folder as frames name their files (as imported, and with links resolved).
_PACKAGE_DIRS = tuple({os.path.dirname(os.path.abspath(__file__)) + os.sep,
                       os.path.dirname(os.path.realpath(__file__)) + os.sep})


def warn(message: str) -> None:
    """Emit a :class:`PhysmocapWarning` (shown on stderr by default), naming the bundled clip
    ``example`` (:func:`~physmocap.resources.display_text`).

    The warning is attributed to the first caller outside physmocap (the user's line that
    called the library), so Python's default format shows that line, not this package's
    ``warn(...)`` call; the command line prints the message alone.
    """
    level, frame = 2, sys._getframe(1)
    while frame is not None and frame.f_code.co_filename.startswith(_PACKAGE_DIRS):
        level += 1
        frame = frame.f_back
    from .resources import display_text

    text = display_text(message)  # the bundled clip as "example", not its installed path
    warnings.warn(text, PhysmocapWarning, stacklevel=level if frame is not None else 2)


def progress_enabled() -> bool:
    """True when progress bars should be drawn (stderr is a terminal or forced)."""
    force = os.environ.get("PHYSMOCAP_PROGRESS")
    if force is not None:
        return force not in ("0", "", "no", "false")
    return sys.stderr.isatty()
