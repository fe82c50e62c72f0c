#!/usr/bin/env python3
"""Fuzzing campaign: seeded mutations of real inputs through the command line.

Every case is a mutated copy of a real file (the bundled BVH walk, a tracker CSV and an MCAP
made from it, and the shared C3D/TRC recordings where ../shared is present), run through
`physmocap inspect` and `physmocap convert` in a child process under a CPU-time and memory
limit.  A case passes when it ends in success (exit 0) or in exactly one `physmocap: error:`
line with exit 2; anything else (a traceback, another exit status, a signal, a timeout) is a
failure, saved under --keep for replay.

Mutations: truncation, byte flips, deleted / duplicated / swapped lines, numbers replaced by
extreme values (1e308, -1e308, nan, inf, 400-digit integers, 0, -0), header counts changed.

Usage:  python scripts/fuzz.py [--cases 200] [--seconds 0] [--seed 0] [--keep DIR]
(--seconds > 0 runs until that budget instead of a number of cases)
"""

from __future__ import annotations

import argparse
import collections
import os
import random
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
EXTREMES = ["1e308", "-1e308", "nan", "inf", "-inf", "0", "-0", "9" * 400, "1e-300", "-1", "3.4e38", "1e20"]
NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
CPU_SECONDS = 60
MEMORY_BYTES = 3 * 1024**3


def seeds(work: Path) -> list[Path]:
    """The real files mutations start from (made once per campaign)."""
    from physmocap.resources import resolve_input

    out = [resolve_input("example")]
    walk = work / "walk.bvh"
    shutil.copy(out[0], walk)
    for suffix in (".csv", ".mcap"):
        target = work / f"walk{suffix}"
        subprocess.run([sys.executable, "-m", "physmocap", "convert", str(walk), str(target), "--end", "60"],
                       capture_output=True, timeout=120)
        if target.exists():
            out.append(target)
    for name in ("vicon_upperbody.trc",):
        if (DATA / name).exists():
            out.append(DATA / name)
    return out


def mutate(data: bytes, rng: random.Random) -> bytes:
    kind = rng.choice(["truncate", "flip", "lines", "number", "number", "number"])
    if kind == "truncate" or not data:
        return data[: rng.randrange(0, max(1, len(data)))]
    if kind == "flip":
        b = bytearray(data)
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b)
    if kind == "lines":
        lines = data.split(b"\n")
        i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
        op = rng.choice(["delete", "duplicate", "swap"])
        if op == "delete":
            del lines[i]
        elif op == "duplicate":
            lines.insert(i, lines[j])
        else:
            lines[i], lines[j] = lines[j], lines[i]
        return b"\n".join(lines)
    matches = list(NUMBER.finditer(data[:200000]))
    if not matches:
        return data
    m = rng.choice(matches)
    return data[: m.start()] + rng.choice(EXTREMES).encode() + data[m.end():]


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_CPU, (CPU_SECONDS, CPU_SECONDS))
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_BYTES, MEMORY_BYTES))


def run_case(path: Path, command: str, work: Path) -> tuple[str, str]:
    """``(outcome, detail)``: outcome is "ok", "error" or "FAIL"."""
    argv = [sys.executable, "-m", "physmocap", command, str(path)]
    if command == "convert":
        argv.append(str(work / "out.bvh"))
    try:
        r = subprocess.run(argv, capture_output=True, text=True, timeout=CPU_SECONDS + 30, preexec_fn=_limits)
    except subprocess.TimeoutExpired:
        return "FAIL", "timeout"
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("physmocap: error:")]
    if r.returncode == 0 and "Traceback" not in r.stderr:
        return "ok", ""
    if r.returncode == 2 and len(errors) == 1 and "Traceback" not in r.stderr:
        return "error", errors[0][:120]
    tail = (r.stderr.strip().splitlines() or ["(no output)"])[-1]
    return "FAIL", f"exit {r.returncode}: {tail[:200]}"


def campaign(cases: int, seconds: float, seed: int, keep: Path | None, out=sys.stdout) -> collections.Counter:
    rng = random.Random(seed)
    counts: collections.Counter = collections.Counter()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        base = seeds(work)
        start = time.monotonic()
        n = 0
        while (seconds > 0 and time.monotonic() - start < seconds) or (seconds <= 0 and n < cases):
            src = rng.choice(base)
            data = src.read_bytes()
            for _ in range(rng.randint(1, 3)):
                data = mutate(data, rng)
            case = work / f"case{n}{src.suffix}"
            case.write_bytes(data)
            command = rng.choice(["inspect", "convert"])
            outcome, detail = run_case(case, command, work)
            counts[(src.suffix, outcome)] += 1
            if outcome == "FAIL":
                print(f"FAIL case {n} ({src.name}, {command}): {detail}", file=out, flush=True)
                if keep is not None:
                    keep.mkdir(parents=True, exist_ok=True)
                    shutil.copy(case, keep / case.name)
            case.unlink()
            n += 1
    return counts


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=200)
    ap.add_argument("--seconds", type=float, default=0.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", type=Path, default=None, help="save failing cases here")
    args = ap.parse_args()
    counts = campaign(args.cases, args.seconds, args.seed, args.keep)
    total = sum(counts.values())
    print(f"{total} cases")
    for (fmt, outcome), n in sorted(counts.items()):
        print(f"  {fmt:6s} {outcome:6s} {n}")
    return 1 if any(o == "FAIL" for (_, o) in counts) else 0


if __name__ == "__main__":
    sys.exit(main())
