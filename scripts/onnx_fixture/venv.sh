#!/usr/bin/env bash
# Provision a Python venv with the pinned `onnx` package, used only to regenerate the ONNX test fixture.
# Idempotent; prints the python path. Usage: scripts/onnx_fixture/venv.sh [VENV_DIR] (default target/venv-onnx).
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
venv="${1:-$repo/target/venv-onnx}"
version="1.19.1"
py="$venv/bin/python"
if [ -x "$py" ] && "$py" -c "import onnx; assert onnx.__version__ == '$version'" 2>/dev/null; then
  echo "$py"
  exit 0
fi
mkdir -p "$(dirname "$venv")"
exec 9>"$venv.lock"
flock 9
python3 -m venv "$venv" >&2
"$py" -m pip install --quiet "onnx==$version" >&2
"$py" -c "import onnx" >&2
echo "$py"
