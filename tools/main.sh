#!/usr/bin/env bash
# README command 1: set up .venv, then run the main job on the shipped default bag:
# replay it through the identifier (the live node's EKF, then the batch refinement) and print
# the coefficient table against the truth and the paper, then write the validation report
# (report/report.md, the same as one self-contained report.html, PNG figures: convergence,
# validation against the measurements of the bag's final 25 %, held out from identification,
# the true model on a held-out manoeuvre, NIS, adapted noise).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
exec .venv/bin/python -m auv_ident report --bag bags/nps_auv2_ident --out report --force "$@"
