#!/usr/bin/env bash
# Provision a Python venv with OpenCASCADE (cadquery-ocp-novtk 8.0.1.1.0, hash-pinned in
# requirements.txt) for the scripts beside this one (bench.py, make_fixtures.py). Cell itself
# provisions its own copy in its cache (perception/src/part/step_kernel.rs); this one is for the
# bench and the fixtures. Idempotent; prints the python path.
# Usage: scripts/step_import/venv.sh [VENV_DIR]   (default <repo>/target/venv-step)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
exec "$repo/scripts/pinned_venv.sh" "${1:-$repo/target/venv-step}" \
  "import importlib.metadata as m, OCP.STEPControl; assert m.version('cadquery-ocp-novtk') == '8.0.1.1.0'" \
  --no-deps --only-binary=:all: --require-hashes -r "$here/requirements.txt"
