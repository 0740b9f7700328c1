#!/usr/bin/env bash
# Creates training/.venv with the exact packages of training/requirements.txt.
# Idempotent: a stamp file holds the sha256 of the requirements; when it matches, nothing is done.
# The torch wheel is the CUDA build (~3 GB installed); it runs on CPU as well.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv"
req="$here/requirements.txt"
stamp="$venv/.requirements.sha256"
want="$(sha256sum "$req" | cut -d' ' -f1)"
if [[ -f "$stamp" && "$(cat "$stamp")" == "$want" && -x "$venv/bin/python" ]]; then
    echo "training/.venv is up to date ($want)"
    exit 0
fi
if [[ ! -x "$venv/bin/python" ]]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --disable-pip-version-check -r "$req"
"$venv/bin/python" -c "import torch, onnx, onnxruntime, numpy, PIL; print('torch', torch.__version__, 'cuda' if torch.cuda.is_available() else 'cpu')"
echo "$want" > "$stamp"
echo "training/.venv ready"
