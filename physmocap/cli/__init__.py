"""The ``physmocap`` command line.

Each sub-command lives in its own module in this package and exposes
``register(subparsers)``, which adds its parser and sets ``func`` to a callable
taking the parsed arguments and returning an exit status.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import warnings
from typing import Sequence

from ..errors import OutputError, PhysmocapError, PhysmocapWarning

#: Sub-command modules, in the order ``physmocap --help`` lists them.
COMMAND_MODULES = (
    "inspect",
    "convert",
    "character",
    "retarget",
    "solve",
    "report",
    "replay",
    "preview",
    "view",
    "clean",
    "batch",
)


def _format_warning(message, category, filename, lineno, line=None):  # noqa: ANN001
    if issubclass(category, PhysmocapWarning):
        return f"physmocap: warning: {message}\n"
    return f"{category.__name__}: {message}\n"


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line on stderr (like every other physmocap error), status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        where = f"{self.prog.split(' ', 1)[1]}: " if " " in self.prog else ""
        sys.stderr.write(f"physmocap: error: {where}{message} (see {self.prog} --help)\n")
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="physmocap",
        description="Turn solved motion capture into clean, physically valid character motion.",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"physmocap {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"{__name__}.{name}":
                continue  # command not built yet
            raise
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``physmocap`` console script.  Warnings print as
    ``physmocap: warning: ...`` while it runs; Python's own format is back when it returns
    (a program that calls it keeps its warnings as they were)."""
    previous = warnings.formatwarning
    warnings.formatwarning = _format_warning
    terminate = _on_sigterm()
    try:
        return _run(argv)
    finally:
        warnings.formatwarning = previous
        if terminate is not None:
            signal.signal(signal.SIGTERM, terminate)


class Terminated(BaseException):
    """SIGTERM while a command runs (``kill``, ``timeout``, a job scheduler): raised where the
    command is, so that every half-written output is removed on the way out, as on Ctrl-C."""


def _on_sigterm():
    """Turn SIGTERM into :class:`Terminated` while :func:`main` runs (in the main thread only,
    and only where SIGTERM has its default action: a caller that ignores it, or handles it
    itself, keeps its own); returns the handler to restore (None: none installed)."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None
    if signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        return None

    def raise_terminated(signum, frame):
        raise Terminated()

    return signal.signal(signal.SIGTERM, raise_terminated)


def _run(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    try:
        status = args.func(args)
    except PhysmocapError as exc:
        if exc.path is None and isinstance(getattr(args, "input", None), str) and not isinstance(exc, OutputError):
            exc.path = args.input  # every message names a file: the command's input unless another is named
        print(f"physmocap: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("physmocap: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print("physmocap: terminated", file=sys.stderr)
        return 143
    except BrokenPipeError:
        return 0
    except OSError as exc:  # disk full, quota, file too large, permission: one line, not a traceback
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"physmocap: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    return int(status or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
