#!/usr/bin/env bash
# Provision a Python venv with the validators of deploy/: kubernetes-validate (the Kubernetes
# manifests against the Kubernetes OpenAPI schemas) and dockerfile-parse (the Containerfile).
# Idempotent: returns at once when the venv already has both at the pinned versions.
# Usage: scripts/deploy_check/venv.sh [VENV_DIR]   (default: <repo>/target/venv-deploy-check); prints the python path.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
kv="1.37.0"
dp="2.0.1"
exec "$repo/scripts/pinned_venv.sh" "${1:-$repo/target/venv-deploy-check}" \
  "import importlib.metadata as m; assert m.version('kubernetes-validate') == '$kv'; assert m.version('dockerfile-parse') == '$dp'; import kubernetes_validate, dockerfile_parse" \
  "kubernetes-validate==$kv" "dockerfile-parse==$dp"
