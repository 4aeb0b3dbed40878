#!/usr/bin/env bash
# Set up .venv and run the whole test suite. DDS stays on loopback: every process gets
# ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, and test/conftest.py gives the run its own
# ROS_DOMAIN_ID and ROS_LOG_DIR and cleans Fast DDS shared memory afterwards.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
unset ROS_LOCALHOST_ONLY
exec .venv/bin/python -m pytest -q -p no:cacheprovider "$@"
