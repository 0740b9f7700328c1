#!/usr/bin/env bash
# Provision a Python venv holding pinned packages from PyPI (by package name), once: the scripts
# beside this one (ur_rtde/, onnx_fixture/, deploy_check/) name their venv, their pins and a
# Python check that they are present. Idempotent and safe to run concurrently (flock); prints the
# venv's python path on stdout, everything else on stderr.
# Usage: scripts/pinned_venv.sh VENV_DIR CHECK_PY REQUIREMENT...
set -euo pipefail
[ $# -ge 3 ] || {
  echo "usage: pinned_venv.sh VENV_DIR CHECK_PY REQUIREMENT..." >&2
  exit 2
}
venv=$1
check=$2
shift 2
py="$venv/bin/python"
ready() { [ -x "$py" ] && "$py" -c "$check" 2>/dev/null; }
if ready; then
  echo "$py"
  exit 0
fi
mkdir -p "$(dirname "$venv")"
exec 9>"$venv.lock"
flock 9
if ! ready; then
  python3 -m venv "$venv" >&2
  "$py" -m pip install --quiet "$@" >&2
fi
"$py" -c "$check" >&2
echo "$py"
