#!/usr/bin/env bash
# The "lowest" job: install exactly the lowest versions pyproject.toml declares (every ">=X"
# floor of the dependencies and of the test extra pinned to "==X"), on the lowest Python it
# declares, into a throwaway venv, and run the test suite there.  A floor that does not
# install or pass is not honest: raise it (after testing the new one with this script).
#
#   scripts/lowest_deps.sh                  # whole suite (about 4 minutes once installed)
#   scripts/lowest_deps.sh tests/test_retarget.py -x
#   PYTHON=python3.10 LOWEST_VENV=/tmp/lowest scripts/lowest_deps.sh
#
# Package registries only (PyPI through pip); the venv is rebuilt on every run.
# Arguments go to pytest; -h/--help first prints this text and exits (nothing deleted).
set -euo pipefail
if [[ "${1:-}" == "-h" || "${1:-}" == "--help" ]]; then
    sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"
    exit 0
fi
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.10}
VENV=${LOWEST_VENV:-/tmp/physmocap-lowest}
if ! "$PY" -c "" 2>/dev/null; then
    echo "lowest: $PY is not available; using python3 ($(python3 --version)), not the lowest Python declared" >&2
    PY=python3
fi
rm -rf "$VENV"
"$PY" -m venv "$VENV"
"$VENV/bin/python" -m pip install --quiet --upgrade pip
# ">=X" -> "==X" for [project] dependencies and the [test] extra (markers kept)
mapfile -t PINS < <("$VENV/bin/python" - <<'PYEOF'
import re
text = open("pyproject.toml", encoding="utf-8").read()
deps = re.search(r"(?ms)^dependencies = \[(.*?)^\]", text).group(1)
test = re.search(r"(?m)^test = \[(.*?)\]", text).group(1)
for req in re.findall(r'"([^"]+)"', deps + test):
    name, rest = re.match(r"([A-Za-z0-9_.\-]+)(.*)", req).groups()
    spec, _, marker = rest.partition(";")
    floor = re.search(r">=\s*([0-9][^,\s]*)", spec)
    pin = f"{name}=={floor.group(1)}" if floor else name
    print(pin + (f"; {marker.strip()}" if marker.strip() else ""))
PYEOF
)
echo "lowest: ${PINS[*]}" >&2
"$VENV/bin/python" -m pip install --quiet "${PINS[@]}"
"$VENV/bin/python" -m pip install --quiet --no-deps -e .
"$VENV/bin/python" -m pip check
"$VENV/bin/python" -m pip list --format=freeze >&2
"$VENV/bin/python" -m pytest -q -p no:warnings "$@"
