#!/usr/bin/env bash
# Gradescope runs this once, as root, when it builds the autograder's image (Ubuntu): it
# installs the sandbox's tools and websim from its wheel, which you upload with this folder
# (build it once: pip wheel . --no-deps -w dist; copy dist/websim-*.whl here).
# docs/grading.md, "Gradescope".
set -euo pipefail
apt-get update
apt-get install -y --no-install-recommends bubblewrap util-linux libseccomp2 python3 python3-venv
python3 -m venv /opt/websim
/opt/websim/bin/pip install --no-cache-dir /autograder/source/websim-*.whl   # with roslibpy, pyseccomp
