#!/usr/bin/env bash
# Re-render a `cell dataset` BOP feeder split with Blender Cycles (issue 45): provisions the bpy
# venv (venv.sh), writes the board's print with `cell board`, and runs render.py, which refuses a
# set whose instance masks do not line up with the source's mask_visib.
# Usage: scripts/cycles_render/run.sh SOURCE OUT [render.py options: --look soft|hard|window|dim --frames N
#        --samples S --seed K --scale F --min-iou T --threads N]
#   e.g. cell dataset --out D --seed 2 --train-crops 0 --test-crops 0 --train-overviews 0 \
#          --test-overviews 0 --test-feeder 30
#        scripts/cycles_render/run.sh D D-cycles-soft --look soft
# Environment: CELL (the cell binary; default: built with cargo run --release), BOARD (default
# scenarios/boards/seed.toml, the board `cell dataset` renders), CATALOG (default
# scenarios/parts/usbc.toml).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
[ $# -ge 2 ] || {
  sed -n '2,12p' "${BASH_SOURCE[0]}" >&2
  exit 2
}
py=$("$here/venv.sh")
board="${BOARD:-$repo/scenarios/boards/seed.toml}"
catalog="${CATALOG:-$repo/scenarios/parts/usbc.toml}"
svg="$(mktemp --suffix=.svg)"
trap 'rm -f "$svg"' EXIT
if [ -n "${CELL:-}" ]; then
  "$CELL" board "$board" --out "$svg" >&2
else
  (cd "$repo" && cargo run --release -q -p cell -- board "$board" --out "$svg" >&2)
fi
src=$1
out=$2
shift 2
exec "$py" "$here/render.py" "$src" "$out" --board-svg "$svg" --board "$board" --catalog "$catalog" "$@"
