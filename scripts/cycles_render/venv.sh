#!/usr/bin/env bash
# Provision a Python 3.11 venv with Blender 4.5.15 LTS as a module (bpy from PyPI, hash-pinned in
# requirements.txt) for render.py. Idempotent; prints the python path.
# Usage: scripts/cycles_render/venv.sh [VENV_DIR]   (default <repo>/target/venv-cycles)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
command -v python3.11 >/dev/null || {
  echo "scripts/cycles_render/venv.sh: bpy 4.5 needs Python 3.11 (python3.11 not on PATH)" >&2
  exit 2
}
# pinned_venv.sh makes the venv with `python3`: make that 3.11 whatever the default is.
shim="$(mktemp -d)"
trap 'rm -rf "$shim"' EXIT
ln -s "$(command -v python3.11)" "$shim/python3"
PATH="$shim:$PATH" "$repo/scripts/pinned_venv.sh" "${1:-$repo/target/venv-cycles}" \
  "import importlib.metadata as m, bpy; assert m.version('bpy') == '4.5.15'" \
  --no-deps --only-binary=:all: --require-hashes -r "$here/requirements.txt"
