#!/usr/bin/env bash
# Install what the tests need, then run the whole suite: lint, types, tests.
# This is the README's test command; .ci/run calls it on a clean checkout.
set -euo pipefail
cd "$(dirname "$0")/.."

python3 -m pip install --quiet --disable-pip-version-check -e '.[test]'

# roslibjs for the Node tests (tests/node/), pinned by web-interface/package-lock.json. npm
# keeps a copy of the lock it installed as node_modules/.package-lock.json: install only when
# that is missing or older than the lock. Without node, tests/test_roslibjs.py is skipped.
lock=web-interface/package-lock.json
if command -v node >/dev/null && [ "$lock" -nt web-interface/node_modules/.package-lock.json ]; then
    (cd web-interface && npm ci --no-audit --no-fund --loglevel=error >/dev/null)
fi

python3 -m ruff check .
python3 -m mypy
python3 -m pytest "$@"
