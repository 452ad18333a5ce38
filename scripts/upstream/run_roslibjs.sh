#!/usr/bin/env bash
# Run roslibjs's server-facing tests against `websim serve`, plain and with --ros, and print a
# per-test summary from vitest's junit XML:
#  - 2.x: /work/upstream/roslibjs-2.x (test/examples/*.example.ts and test/service.test.ts of
#    roslibjs 2.x against npm roslib 2.1.0, ROS_DISTRO=jazzy as upstream's ROS 2 CI sets it);
#  - 1.4.1: /work/upstream/roslibjs-1.4.1 (a checkout of tag 1.4.1: test/examples and
#    test/service.test.js; upstream ran it on ROS 1 noetic only, it has no ROS 2 switches).
# Needs those folders set up with npm (see README.md here). Ports 9090 and 8080 must be free.
# Usage: bash scripts/upstream/run_roslibjs.sh     MODES="plain" SUITES="2.x" to narrow
set -uo pipefail
source "$(dirname "$0")/lib.sh"
trap stop_all EXIT INT TERM
status=0
for mode in $(modes); do
    for suite in ${SUITES:-2.x 1.4.1}; do
        dir=$upstream/roslibjs-$suite
        [ -d "$dir/node_modules" ] || { echo "no roslibjs $suite suite at $dir (see README.md)" >&2; status=1; continue; }
        label="roslibjs-$suite/$mode"
        run_header "$label"
        start_websim "$mode" "$results/websim-roslibjs-$suite-$mode.log" || exit 1
        start_fixtures "$mode" "roslibjs-$suite-$mode" || { stop_all; exit 1; }
        xml="$results/roslibjs-$suite-$mode.xml"
        rm -f "$xml"
        if [ "$suite" = 2.x ]; then
            (cd "$dir" && ROS_DISTRO=jazzy JUNIT_OUT="$xml" timeout 600 npx vitest run) \
                > "$results/roslibjs-$suite-$mode.out" 2>&1 || status=1
        else
            (cd "$dir" && timeout 600 npx vitest run --reporter=verbose --reporter=junit \
                --outputFile.junit="$xml" test/examples test/service.test.js) \
                > "$results/roslibjs-$suite-$mode.out" 2>&1 || status=1
        fi
        stop_all
        summarise "$label" "$xml"
    done
done
exit $status
