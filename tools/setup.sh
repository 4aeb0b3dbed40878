#!/usr/bin/env bash
# Create/refresh the project's virtual environment in .venv (git-ignored) and install
# auv_ident into it (editable). Idempotent: reinstalls only when requirements.txt changed.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
stamp=.venv/.auv_ident_requirements.sha
want=$( (cat requirements.txt setup.py) | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  log=$(mktemp)
  echo "[setup] installing dependencies into .venv (about 1 min on a fresh machine)..." >&2
  if ! { .venv/bin/python -m pip install -q --upgrade pip \
         && .venv/bin/python -m pip install -q -r requirements.txt \
         && .venv/bin/python -m pip install -q --no-deps -e . ; } >"$log" 2>&1; then
    grep -v "WARNING: Location" "$log" >&2 || true
    echo "[setup] pip install failed (log above)" >&2
    exit 1
  fi
  rm -f "$log"
  echo "$want" > "$stamp"
fi
