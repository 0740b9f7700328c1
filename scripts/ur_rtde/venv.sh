#!/usr/bin/env bash
# Provision a Python venv with SDU ur_rtde 1.6.5, the independent RTDE peer used by the interop tests.
# Idempotent: returns immediately when the venv already imports rtde_receive at the pinned version.
# Usage: scripts/ur_rtde/venv.sh [VENV_DIR]   (default: <repo>/target/venv-urrtde); prints the python path.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
venv="${1:-$repo/target/venv-urrtde}"
version="1.6.5"
py="$venv/bin/python"
if [ -x "$py" ] && "$py" -c "import importlib.metadata as m, rtde_receive; assert m.version('ur_rtde') == '$version'" 2>/dev/null; then
  echo "$py"
  exit 0
fi
lock="$venv.lock"
mkdir -p "$(dirname "$venv")"
exec 9>"$lock"
flock 9
if ! { [ -x "$py" ] && "$py" -c "import rtde_receive" 2>/dev/null; }; then
  python3 -m venv "$venv" >&2
  "$py" -m pip install --quiet "ur-rtde==$version" >&2
fi
"$py" -c "import rtde_receive, rtde_control, rtde_io" >&2
echo "$py"
