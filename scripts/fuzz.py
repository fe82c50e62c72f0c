#!/usr/bin/env python3
"""Fuzzing campaign: seeded mutations of real inputs through the command line.

Every case is a mutated copy of a real file (the bundled BVH walk; a tracker CSV, JSONL and NPZ
and an MCAP made from it; a trajectory NPZ from `retarget --qpos`; the robot's mapping file; and
the shared TRC recording and the shared C3D's first 60 frames as a `foxglove.PointCloud` marker
MCAP where ../shared is present), run in a child process under a CPU-time and memory limit:
motion files through `physmocap inspect` and `physmocap convert` (the point clouds also through
`physmocap solve`), the
trajectory through `physmocap report`, the mapping through `physmocap character info robot --map`.  A case passes when it ends in success (exit 0) or in exactly one `physmocap: error:`
line with exit 2; anything else (a traceback, another exit status, a signal, a timeout) is a
failure, saved under --keep for replay.

Mutations: truncation, byte flips, deleted / duplicated / swapped lines, numbers replaced by
extreme values (1e308, -1e308, nan, inf, 400-digit integers, 0, -0), header counts changed; and
structural ones that keep the container valid: MCAP skeleton metadata fields and messages
rewritten with values of the wrong type, range or nesting; NPZ arrays replaced by strings,
bytes that are not UTF-8, wrong shapes, 0-d arrays, extreme numbers, dropped, or headers that
lie about their size; TOML entries repeated, nested deeply or given extreme values.

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
    import numpy as np

    from physmocap.resources import mjcf_dir, resolve_input
    from physmocap.sources import load_motion

    out = [resolve_input("example")]
    walk = work / "walk.bvh"
    shutil.copy(out[0], walk)
    from physmocap.export.mcap import write_motion_mcap

    motion = load_motion(walk).slice_frames(0, 60)
    out.append(write_motion_mcap(motion, work / "walk.mcap", compression="none"))
    # tracker files: the walk's joint positions
    pos, names = motion.world_positions(), motion.skeleton.names
    rows = ["time," + ",".join(f"{n}_{a}" for n in names for a in "xyz")]
    rows += [",".join([repr(f / motion.fps)] + [repr(float(v)) for v in pos[f].reshape(-1)]) for f in range(len(pos))]
    (work / "walk.csv").write_text("# units: m\n# up: Z\n# frame: world\n" + "\n".join(rows) + "\n")
    lines = ['{"fps": %r, "units": "m", "up": "Z", "frame": "world"}' % motion.fps]
    lines += ['{"time": %r, "joints": {%s}}' % (f / motion.fps, ", ".join(
        '"%s": [%r, %r, %r]' % (n, *map(float, pos[f, j])) for j, n in enumerate(names))) for f in range(len(pos))]
    (work / "walk.jsonl").write_text("\n".join(lines) + "\n")
    np.savez(work / "walk_tracker.npz", positions=pos, names=np.array(names), fps=np.array(motion.fps),
             units=np.array("m"), up=np.array("Z"), frame=np.array("world"))
    out += [work / "walk.csv", work / "walk.jsonl", work / "walk_tracker.npz"]
    from physmocap.models import load_character

    nq, F = load_character("humanoid").model.nq, 20  # a trajectory NPZ as retarget --qpos writes it
    qpos = np.zeros((F, nq))
    qpos[:, 2], qpos[:, 3] = 0.95, 1.0
    quat = np.zeros((F, 1, 4))
    quat[..., 3] = 1.0
    np.savez(work / "walk_traj.npz", qpos=qpos, fps=np.array(30.0), mjcf_path=np.array("humanoid"),
             source=np.array("example"), source_start=np.array(0), target_names=np.array(["pelvis"]),
             target_positions=np.zeros((F, 1, 3)) + [0, 0, 0.95], target_orientations=quat,
             target_has_orientation=np.array([True]), target_valid=np.ones((F, 1), bool))
    out.append(work / "walk_traj.npz")
    shutil.copy(mjcf_dir() / "robot.map.toml", work / "robot.map.toml")
    out.append(work / "robot.map.toml")
    for name in ("vicon_upperbody.trc",):
        if (DATA / name).exists():
            out.append(DATA / name)
    if (DATA / "cmu_01_01_markers.c3d").exists():  # markers as Foxglove point clouds, labels in metadata
        from physmocap.export.mcap import write_markers_pointcloud_mcap
        from physmocap.sources.markers import read_markers

        rec = read_markers(DATA / "cmu_01_01_markers.c3d").frames(0, 60)
        out.append(write_markers_pointcloud_mcap(rec, work / "markers_cloud.mcap", compression="none"))
    return out


def commands(path: Path) -> list[list[str]]:
    """The command lines a case file goes through (the file's place is ``{}``)."""
    if path.name.endswith(".map.toml"):
        return [["character", "info", "robot", "--map", "{}"], ["inspect", "example", "--map", "{}"]]
    if "traj" in path.stem:
        return [["report", "{}", "--no-source"]]
    if path.stem == "markers_cloud":
        return [["inspect", "{}"], ["convert", "{}", "OUT.bvh"], ["solve", "{}", "-o", "OUT.bvh"]]
    return [["inspect", "{}"], ["convert", "{}", "OUT.bvh"]]


# --- structural mutations: the container stays valid, its contents are hostile ---------------
DEEP = "[" * 5000 + "]" * 5000
HOSTILE_JSON = ['"x"', "5", "-1", "1e308", "-1e308", "9" * 400, "[]", "{}", "null", "true", "[[1, 2]]",
                "[1.5]", "[-5]", "[500]", "1000000", '"\\udcff"', DEEP, "[" + ", ".join(["0"] * 5000) + "]"]


def mutate_mcap(data: bytes, rng: random.Random) -> bytes:
    """Rewrite one skeleton metadata field or one message of an MCAP with a hostile value."""
    import io

    from mcap.reader import make_reader
    from mcap.writer import Writer

    reader = make_reader(io.BytesIO(data))
    out = io.BytesIO()
    w = Writer(out)
    w.start()
    schemas: dict = {}
    chans: dict = {}
    target_msg = rng.randrange(60)
    kind = rng.choice(["meta", "meta", "message"])
    for n, (sch, ch, msg) in enumerate(reader.iter_messages()):
        if sch.id not in schemas:
            schemas[sch.id] = w.register_schema(sch.name, sch.encoding, sch.data)
        if ch.id not in chans:
            chans[ch.id] = w.register_channel(ch.topic, ch.message_encoding, schemas[sch.id], ch.metadata)
        body = msg.data
        if kind == "message" and n == target_msg:
            numbers = list(NUMBER.finditer(body))
            if numbers and rng.random() < 0.7:
                m = rng.choice(numbers)
                body = body[: m.start()] + rng.choice(HOSTILE_JSON).encode() + body[m.end():]
            else:
                body = rng.choice([b"{}", b"[]", b'{"transforms": 5}', DEEP.encode(), body[: len(body) // 2]])
        w.add_message(chans[ch.id], msg.log_time + (rng.choice([0, 10**20 % 2**63]) if n == target_msg else 0),
                      body, msg.publish_time)
    for md in reader.iter_metadata():
        meta = dict(md.metadata)
        if kind == "meta" and meta:
            key = rng.choice(sorted(meta))
            meta[key] = rng.choice(HOSTILE_JSON + [meta[key][: len(meta[key]) // 2]])
        w.add_metadata(md.name, meta)
    w.finish()
    return out.getvalue()


def mutate_npz(data: bytes, rng: random.Random) -> bytes:
    """Replace, drop or lie about one array of an NPZ."""
    import io
    import zipfile

    import numpy as np
    from numpy.lib import format as npformat

    src = zipfile.ZipFile(io.BytesIO(data))
    names = src.namelist()
    victim = rng.choice(names)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", compression=rng.choice([zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED])) as z:
        for name in names:
            body = src.read(name)
            if name == victim:
                op = rng.choice(["string", "bytes", "0d", "shape", "extreme", "drop", "lie", "int", "empty"])
                arr = np.load(io.BytesIO(body), allow_pickle=False)
                buf = io.BytesIO()
                if op == "drop":
                    continue
                if op == "lie":  # a header declaring far more data than the member holds
                    npformat.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False,
                                                         "shape": (10**12,) + arr.shape[1:]})
                    body = buf.getvalue() + body[-64:]
                else:
                    new = {
                        "string": lambda: np.array("thirty"),
                        "bytes": lambda: np.array([b"\xff\xfe"] * max(1, arr.size)),
                        "0d": lambda: np.array(arr.reshape(-1)[0] if arr.size else 0),
                        "shape": lambda: arr.reshape(-1)[: max(0, arr.size - 1)],
                        "extreme": lambda: np.full(arr.shape, rng.choice([1e308, -1e308, np.nan, np.inf, 1e20])),
                        "int": lambda: np.full(arr.shape, rng.choice([-1, 2**62, 0]), dtype=np.int64),
                        "empty": lambda: np.zeros((0,) + arr.shape[1:]),
                    }[op]()
                    np.save(buf, new)
                    body = buf.getvalue()
            z.writestr(name, body)
    return out.getvalue()


def mutate_toml(data: bytes, rng: random.Random) -> bytes:
    """Repeat an entry or a list item, nest a value deeply, or give it an extreme value."""
    lines = data.decode("utf-8").split("\n")
    entries = [i for i, ln in enumerate(lines) if "=" in ln and not ln.lstrip().startswith("#")]
    i = rng.choice(entries)
    key, _, value = lines[i].partition("=")
    op = rng.choice(["dup_line", "dup_item", "deep", "value", "value", "table"])
    if op == "dup_line":
        lines.insert(i, lines[i])
    elif op == "dup_item" and "[" in value:
        first = value[value.index("[") + 1:].split(",")[0].strip(" ]")
        lines[i] = f"{key}= [" + ", ".join([first] * rng.choice([2, 1000])) + "]"
    elif op == "deep":
        lines[i] = f"{key}= " + "[" * 3000 + "]" * 3000
    elif op == "table":
        lines.insert(i, rng.choice(["[joints]", "[contacts]", "[[joints]]", "[character.x]"]))
    else:
        lines[i] = f"{key}= " + rng.choice(['"x"', "1e308", "-1", "9" * 400, "[]", "{}", "true", '"body:"',
                                             '"site:nope"', "nan", "inf"])
    return "\n".join(lines).encode("utf-8")


def structural(path: Path, data: bytes, rng: random.Random) -> bytes:
    suffix = path.suffix.lower()
    try:
        if suffix == ".mcap":
            return mutate_mcap(data, rng)
        if suffix == ".npz":
            return mutate_npz(data, rng)
        if path.name.endswith(".toml"):
            return mutate_toml(data, rng)
    except Exception:  # a seed the structural mutator cannot open (already byte-mutated): keep it
        return data
    return mutate(data, rng)


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


def run_case(path: Path, command: list[str], work: Path) -> tuple[str, str]:
    """``(outcome, detail)``: outcome is "ok", "error" or "FAIL"."""
    out = work / "out"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    argv = [sys.executable, "-m", "physmocap"] + [
        str(path) if a == "{}" else str(out / "out.bvh") if a == "OUT.bvh" else a for a in command
    ]
    try:
        r = subprocess.run(argv, capture_output=True, text=True, timeout=CPU_SECONDS + 30, preexec_fn=_limits,
                           cwd=work)
    except subprocess.TimeoutExpired:
        return "FAIL", "timeout"
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("physmocap: error:")]
    if r.returncode == 0 and "Traceback" not in r.stderr:
        return "ok", ""
    if r.returncode == 2 and len(errors) == 1 and "Traceback" not in r.stderr:
        if any(out.iterdir()):
            return "FAIL", f"exit 2 but left {sorted(p.name for p in out.iterdir())}"
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
            how = "structural" if rng.random() < 0.4 else "bytes"
            if how == "structural":
                data = structural(src, data, rng)
            for _ in range(rng.randint(0 if how == "structural" else 1, 2 if how == "structural" else 3)):
                data = mutate(data, rng)
            suffix = ".map.toml" if src.name.endswith(".map.toml") else src.suffix
            stem = "traj" if "traj" in src.stem else "case"
            case = work / f"{stem}{n}{suffix}"
            case.write_bytes(data)
            command = rng.choice(commands(src))
            outcome, detail = run_case(case, command, work)
            fmt = "map" if suffix == ".map.toml" else f"{suffix}{'(traj)' if stem == 'traj' else ''}"
            counts[(fmt, outcome)] += 1
            if outcome == "FAIL":
                print(f"FAIL case {n} ({src.name}, {how}, {' '.join(command)}): {detail}", file=out, flush=True)
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
        print(f"  {fmt:12s} {outcome:6s} {n}")
    return 1 if any(o == "FAIL" for (_, o) in counts) else 0


if __name__ == "__main__":
    sys.exit(main())
