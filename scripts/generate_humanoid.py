"""Write assets/mjcf/humanoid.xml, scene.xml and humanoid.map.toml from the tables in physmocap.models.

Usage: python scripts/generate_humanoid.py [--check]

With --check nothing is written; the exit status is 1 if a committed file
differs from what the generator produces now.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from physmocap.fileio import atomic_open
from physmocap.models.humanoid_builder import humanoid_xml, mapping_toml, scene_xml

ASSETS = Path(__file__).resolve().parents[1] / "assets" / "mjcf"


def outputs() -> dict[Path, str]:
    return {
        ASSETS / "humanoid.xml": humanoid_xml(),
        ASSETS / "scene.xml": scene_xml("humanoid.xml", "humanoid scene"),
        ASSETS / "humanoid.map.toml": mapping_toml(),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only compare, do not write")
    args = parser.parse_args()
    stale = 0
    for path, text in outputs().items():
        current = path.read_text(encoding="utf-8") if path.exists() else None
        if current == text:
            continue
        if args.check:
            print(f"{path} is out of date", file=sys.stderr)
            stale += 1
        else:
            with atomic_open(path) as fh:
                fh.write(text)
            print(f"wrote {path}", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
