"""``physmocap batch``: retarget a whole folder, glob or manifest, on local processes or Ray."""

from __future__ import annotations

import argparse
import os
import sys

from ..errors import OptionError

FORMATS = (".npz", ".bvh", ".csv", ".mcap")


def register(sub: argparse._SubParsersAction) -> None:
    from .retarget import add_bvh_output_options, add_retarget_options

    p = sub.add_parser(
        "batch",
        help="retarget every file of a folder, glob or manifest (resumable, parallel, Ray)",
        description=(
            "Retarget every capture file of SOURCE (a folder, searched recursively; a quoted glob; or a "
            "manifest: .txt with one input per line, or .csv / .jsonl with input, optional output and "
            "per-file retarget options, paths relative to the manifest) with retarget's options. Outputs "
            "are mirrored under OUTDIR unless the manifest names them; files already done with the same "
            "options are skipped (--force redoes them); a failing "
            "file is recorded and the others go on; OUTDIR/summary.csv and summary.json list every file's "
            "figures."
        ),
    )
    p.add_argument("source", metavar="SOURCE", help="folder, glob pattern or manifest (.txt, .csv, .jsonl)")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="output folder")
    p.add_argument("--format", default="npz", choices=[f[1:] for f in FORMATS], help="output format (default npz)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes (default: one per core)")
    p.add_argument("--force", action="store_true", help="redo files already done")
    p.add_argument("--ray", metavar="ADDRESS", help="run as Ray tasks: 'local' starts Ray here, 'auto' joins the running "
                   "cluster, or a cluster address (needs physmocap[cluster])")
    add_bvh_output_options(p)
    add_retarget_options(p)
    p.set_defaults(func=run)


#: Arguments that are the batch's own, not the per-file retarget options.
OWN = {"source", "output", "format", "jobs", "force", "ray", "func", "command", "quiet", "input"}


def run(args: argparse.Namespace) -> int:
    from ..batch import plan, run_batch
    from .retarget import check_option_files, config_from_args

    if args.jobs < 1:
        raise OptionError("--jobs must be at least 1")
    config_from_args(args)  # a bad option is one error now, not one per file
    check_option_files(args)
    _check_character(args)
    options = {k: v for k, v in sorted(vars(args).items()) if k not in OWN}
    given = [f"--{name}" for name in ("up", "units") if options.get(name) is not None]
    if given and args.format != "bvh":  # said once here: the files' own warnings are not shown
        from ..errors import warn

        verb = "applies" if len(given) == 1 else "apply"
        warn(f"{' and '.join(given)} {verb} to BVH outputs only: ignored for --format {args.format} "
             "(a manifest's per-file outputs ending in .bvh take them)")
    jobs = plan(args.source, args.output, "." + args.format, options)
    results = run_batch(
        jobs, args.output, options, workers=args.jobs, force=args.force, ray=args.ray,
        progress=False if args.quiet else None,
    )
    failed = [r for r in results if r.status == "failed"]
    frames = sum(r.frames for r in results if r.status == "done")
    print(f"{len(results) - len(failed)} of {len(results)} files done ({frames} frames); summary in "
          f"{os.path.join(args.output, 'summary.csv')}", file=sys.stderr)
    for r in failed:
        shown = _shown(r.input, args.source)  # spelt as the user spelt the source
        error = _failure(r).replace(r.input, shown)
        named = error.startswith(f"{shown}:")  # most errors already name their file
        print(f"failed: {error}" if named else f"failed: {shown}: {error}", file=sys.stderr)
    return 0 if not failed else 1


def _shown(path: str, source: str) -> str:
    """``path`` (jobs hold absolute paths) relative to the working directory where the user
    gave a relative ``source`` (folder, glob or manifest), else as it is."""
    if os.path.isabs(source):
        return path
    try:
        return os.path.relpath(path)
    except ValueError:  # another drive
        return path


def _check_character(args: argparse.Namespace) -> None:
    """Load the batch's character (``--character``, ``--map``) once: one that cannot be
    loaded is one error now, not a failure per file.

    Raises:
        PhysmocapError: The character's own error.
    """
    from ..models import load_character

    load_character(args.character, args.map)


def _failure(result) -> str:
    """A failed file's error, with its frame when known and not already named."""
    if result.frame is None or f"frame {result.frame}:" in result.error:
        return result.error
    return f"{result.error} (frame {result.frame})"
