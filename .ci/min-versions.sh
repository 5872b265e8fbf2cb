#!/usr/bin/env bash
# Proves the lower bounds in pyproject.toml: builds a separate venv with every dependency
# (runtime, the `all` and `test` extras, and the build backend) at exactly the minimum that
# pyproject.toml declares (.ci/min_pins.py turns each `>=` into `==`), installs dischargelab
# into it without letting pip pull anything newer, and runs the test suite there.
# Usage: bash .ci/min-versions.sh [PYTEST ARGS...]    (default: the whole suite)
# MIN_VENV=path chooses where the venv goes (default .venv/min-versions, recreated each run).
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
VENV=${MIN_VENV:-.venv/min-versions}

rm -rf "$VENV"
"$PYTHON" -m venv "$VENV"
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$PYTHON" .ci/min_pins.py --build all test > "$VENV/min-pins.txt"
echo "min-versions: installing the declared lower bounds:" $(cat "$VENV/min-pins.txt")
# The pins are direct dependencies only; their own dependencies resolve as pip chooses.
"$VENV/bin/python" -m pip install --quiet -r "$VENV/min-pins.txt"
# --no-build-isolation: built with the pinned (minimum) setuptools; --no-deps: nothing newer.
"$VENV/bin/python" -m pip install --quiet --no-deps --no-build-isolation -e .
"$VENV/bin/python" -m pip check
"$VENV/bin/python" -m pip list --format=freeze > "$VENV/installed.txt"
if [ "$#" -eq 0 ]; then set -- -q; fi
"$VENV/bin/python" -m pytest -p no:cacheprovider "$@"
