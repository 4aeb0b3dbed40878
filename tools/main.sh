#!/usr/bin/env bash
# README command 1: set up .venv, then run the main job on the shipped default.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
exec .venv/bin/python -m auv_ident simulate --vehicle nps_auv2 --maneuver zigzag --duration 200 --seed 1 "$@"
