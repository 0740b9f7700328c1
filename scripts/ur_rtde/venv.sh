#!/usr/bin/env bash
# Provision a Python venv with SDU ur_rtde 1.6.5, the independent RTDE peer used by the interop tests.
# Idempotent: returns immediately when the venv already imports rtde_receive at the pinned version.
# Usage: scripts/ur_rtde/venv.sh [VENV_DIR]   (default: <repo>/target/venv-urrtde); prints the python path.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
version="1.6.5"
exec "$repo/scripts/pinned_venv.sh" "${1:-$repo/target/venv-urrtde}" \
  "import importlib.metadata as m, rtde_receive, rtde_control, rtde_io; assert m.version('ur_rtde') == '$version'" \
  "ur-rtde==$version"
