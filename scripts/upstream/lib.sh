# Shared by run_roslibpy.sh and run_roslibjs.sh (sourced): start and stop `websim serve` and
# the fixture nodes, summarise junit XML. Not a script of its own.
#
# websim runs from this checkout (PYTHONPATH), on the default ports the upstream suites
# hard-code (ws://localhost:9090; the page on :8080). With --ros it needs rclpy and tf2_msgs
# (pip install '.[ros]' then bash scripts/build_tf2_msgs.sh); the ROS graph is kept to this
# machine and to its own domain (WEBSIM_UPSTREAM_DOMAIN, 77) so other ROS processes here do
# not join it.

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
main=$(cd "$here/../.." && pwd)
upstream=${UPSTREAM_DIR:-/work/upstream}
results=${RESULTS_DIR:-$upstream/results}
python=${PYTHON:-python3}
mkdir -p "$results"
export PYTHONPATH="$main${PYTHONPATH:+:$PYTHONPATH}"
export ROS_DOMAIN_ID=${WEBSIM_UPSTREAM_DOMAIN:-77}
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_LOCALHOST_ONLY=1

websim_pid=""
fixture_pid=""
rclpy_pid=""

# Which modes to run: "plain", and "ros" when rclpy and tf2_msgs import (MODES overrides).
modes() {
    if [ -n "${MODES:-}" ]; then echo "$MODES"; return; fi
    if "$python" -c 'import rclpy, tf2_msgs.msg' 2>/dev/null; then
        echo "plain ros"
    else
        if "$python" -c 'import rclpy' 2>/dev/null; then
            echo "upstream: rclpy imports but tf2_msgs does not: run bash scripts/build_tf2_msgs.sh for --ros" >&2
        else
            echo "upstream: rclpy does not import: --ros skipped (pip install '.[ros]')" >&2
        fi
        echo "plain"
    fi
}

port_busy() {
    (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null
}

# start_websim MODE LOG: `websim serve` (plus --ros for MODE=ros); waits for /healthz.
start_websim() {
    local mode=$1 log=$2 extra=()
    [ "$mode" = ros ] && extra=(--ros)
    for port in 9090 8080; do
        if port_busy "$port"; then
            echo "upstream: port $port is in use; stop what listens there first" >&2
            return 1
        fi
    done
    setsid "$python" -m websim.cli serve "${extra[@]}" > "$log" 2>&1 &
    websim_pid=$!
    for _ in $(seq 1 150); do
        if "$python" -c 'import urllib.request; urllib.request.urlopen("http://127.0.0.1:8080/healthz", timeout=1)' 2>/dev/null; then
            return 0
        fi
        if ! kill -0 "$websim_pid" 2>/dev/null; then
            echo "upstream: websim serve exited; its log:" >&2; cat "$log" >&2; return 1
        fi
        sleep 0.2
    done
    echo "upstream: websim serve did not answer /healthz in 30 s" >&2
    return 1
}

# start_fixture LOG [ARGS...]: fixture_nodes.py, the helper nodes as one rosbridge client.
start_fixture() {
    local log=$1; shift
    setsid "$python" "$here/fixture_nodes.py" "$@" > "$log" 2>&1 &
    fixture_pid=$!
    for _ in $(seq 1 50); do
        grep -q serving "$log" 2>/dev/null && return 0
        sleep 0.2
    done
    echo "upstream: fixture_nodes did not connect; its log:" >&2; cat "$log" >&2; return 1
}

# start_rclpy_fixture LOG: with --ros, fixture_rclpy.py (/add_two_ints_server, and /fibonacci
# when example_interfaces imports).
start_rclpy_fixture() {
    setsid "$python" "$here/fixture_rclpy.py" > "$1" 2>&1 &
    rclpy_pid=$!
    for _ in $(seq 1 50); do
        grep -q serving "$1" 2>/dev/null && return 0
        sleep 0.2
    done
    echo "upstream: fixture_rclpy did not start; its log:" >&2; cat "$1" >&2; return 1
}

stop_all() {
    for pid in $rclpy_pid $fixture_pid $websim_pid; do
        if kill -0 "$pid" 2>/dev/null; then
            kill -TERM -- "-$pid" 2>/dev/null || kill -TERM "$pid" 2>/dev/null
            for _ in $(seq 1 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.2; done
            kill -KILL -- "-$pid" 2>/dev/null || true
        fi
    done
    rclpy_pid=""; fixture_pid=""; websim_pid=""
}

run_header() {
    echo "== $1 | websim $(git -C "$main" log -1 --format=%h) (+$(git -C "$main" status --porcelain | wc -l) uncommitted) | $(date -u +%FT%TZ)"
}

# summarise LABEL XML: the per-test lines, or a line saying the runner left no XML.
summarise() {
    if [ -f "$2" ]; then
        "$python" "$here/junit_summary.py" "$@"
    else
        echo "$1: no junit XML (the runner was killed or crashed; see its .out in $results)"
    fi
}

# start_fixtures MODE NAME: for MODE=ros the rclpy nodes first; then fixture_nodes.py, which
# leaves /fibonacci to the graph when fixture_rclpy.py serves it there.
start_fixtures() {
    local mode=$1 name=$2 args=()
    if [ "$mode" = ros ]; then
        start_rclpy_fixture "$results/rclpy-$name.log" || return 1
        if grep -q "action /fibonacci" "$results/rclpy-$name.log"; then
            args=(--without-action)
            wait_graph_action /fibonacci || return 1
        fi
    fi
    start_fixture "$results/fixture-$name.log" "${args[@]}"
}

# wait_graph_action NAME: with --ros, wait (15 s at most) until websim's rosapi lists the graph
# action server NAME; DDS discovery of a just-started node takes a few seconds, and a goal sent
# before it is answered "Action NAME does not exist".
wait_graph_action() {
    "$python" - "$1" <<'PY'
import asyncio, json, sys, time
import websockets

async def listed(name):
    async with websockets.connect("ws://127.0.0.1:9090") as ws:
        await ws.send(json.dumps({"op": "call_service", "service": "/rosapi/action_servers",
                                  "id": "w"}))
        reply = json.loads(await asyncio.wait_for(ws.recv(), 5))
        return name in reply.get("values", {}).get("action_servers", [])

deadline = time.monotonic() + 15
while not asyncio.run(listed(sys.argv[1])):
    if time.monotonic() > deadline:
        sys.exit(f"upstream: {sys.argv[1]} not on the graph after 15 s")
    time.sleep(0.5)
PY
}
