#!/usr/bin/env bash
# Install what the tests need, then run the whole suite: lint, types, tests.
# This is the README's test command; .ci/run calls it on a clean checkout.
set -euo pipefail
cd "$(dirname "$0")/.."

python3 -m pip install --quiet --disable-pip-version-check -e '.[test]'

python3 -m ruff check .
python3 -m mypy
python3 -m pytest "$@"
