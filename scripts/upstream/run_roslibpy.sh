#!/usr/bin/env bash
# Run roslibpy's own test suite (the sdist of the roslibpy installed here, unpacked in
# /work/upstream/roslibpy) against `websim serve`, plain and with --ros, once per roslibpy
# transport (twisted, asyncio), and print a per-test summary from pytest's junit XML.
#
# Needs: /work/upstream/roslibpy (pip download --no-deps --no-binary :all: roslibpy==VERSION,
# untarred; see README.md here), pytest, websockets, and pytest-timeout in /work/upstream/pydeps
# (pip install --no-deps --target /work/upstream/pydeps pytest-timeout). Ports 9090 and 8080 must be free.
# Usage: bash scripts/upstream/run_roslibpy.sh      MODES="plain" TRANSPORTS="twisted" to narrow
set -uo pipefail
source "$(dirname "$0")/lib.sh"
suite=$upstream/roslibpy
[ -d "$suite/tests/ros2" ] || { echo "no roslibpy suite at $suite (see README.md)" >&2; exit 2; }
trap stop_all EXIT INT TERM
status=0
for mode in $(modes); do
    for transport in ${TRANSPORTS:-twisted asyncio}; do
        label="roslibpy-$("$python" -c 'import roslibpy; print(roslibpy.__version__)')/$mode/$transport"
        run_header "$label"
        start_websim "$mode" "$results/websim-roslibpy-$mode-$transport.log" || exit 1
        start_fixtures "$mode" "roslibpy-$mode-$transport" || { stop_all; exit 1; }
        xml="$results/roslibpy-$mode-$transport.xml"
        rm -f "$xml"
        # pytest-timeout (installed under $upstream/pydeps) fails a test that hangs, e.g. a
        # roslibpy wait_goal whose result never comes, instead of hanging the run.
        (cd "$suite" && PYTHONPATH="$upstream/pydeps:$PYTHONPATH" ROSLIBPY_TRANSPORT=$transport \
            timeout 600 "$python" -m pytest -p no:cacheprovider --timeout 60 \
            -q -rfE tests/ros2 tests/test_ws_headers.py tests/test_transport.py --junitxml="$xml") \
            > "$results/roslibpy-$mode-$transport.out" 2>&1 || status=1
        stop_all
        summarise "$label" "$xml"
    done
done
exit $status
