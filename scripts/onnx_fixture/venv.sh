#!/usr/bin/env bash
# Provision a Python venv with the pinned `onnx` package, used only to regenerate the ONNX test fixture.
# Idempotent; prints the python path. Usage: scripts/onnx_fixture/venv.sh [VENV_DIR] (default target/venv-onnx).
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
version="1.19.1"
exec "$repo/scripts/pinned_venv.sh" "${1:-$repo/target/venv-onnx}" \
  "import onnx; assert onnx.__version__ == '$version'" "onnx==$version"
