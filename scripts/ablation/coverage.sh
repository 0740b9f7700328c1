#!/usr/bin/env bash
# Coverage of the committed Blender Cycles sets by our renders, per randomisation family, before
# any training (docs/reference/cycles.md, "Before training"): for each configuration a feeder set
# `cell dataset --seed 2 --test-feeder FRAMES --families CONFIG` (the Cycles sets' scenes first),
# then scripts/ablation/coverage.py against cell/tests/fixtures/cycles/{soft,hard}: one row per
# configuration of the Cycles instances inside our 2nd-98th percentile ranges (mean grey level
# and its spread, both), per part kind and look, and their mean.
#
# Usage: scripts/ablation/coverage.sh OUT
# Environment:
#   FRAMES   feeder frames per set [60: about 15 CPU-s a set]
#   CONFIGS  space-separated `--families` values [none all all,-NAME for each family, lights]
#   EXTRA    more `cell dataset` arguments for every set, e.g. "--environment room" []
#   CELL     the cell command [target/release/cell, built if missing]
#   PY       a Python with numpy and Pillow [training/.venv/bin/python, provisioned if missing]
set -euo pipefail
[ $# -eq 1 ] || { sed -n '2,16p' "$0" >&2; exit 2; }
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
out="$(realpath -m "$1")"
cd "$root"
if [[ -n "${PY:-}" ]]; then py="$PY"; else training/provision.sh >/dev/null; py="$root/training/.venv/bin/python"; fi
if [[ -z "${CELL:-}" ]]; then
    [ -x target/release/cell ] || cargo build --release -q -p cell
    CELL="$root/target/release/cell"
fi
read -r -a cell <<< "$CELL"
read -r -a extra <<< "${EXTRA:-}"
frames="${FRAMES:-60}"
if [[ -n "${CONFIGS:-}" ]]; then
    read -r -a configs <<< "$CONFIGS"
else
    configs=(none all)
    for f in lights plating plastic textures distractors sensor; do configs+=("all,-$f"); done
    configs+=(lights)
fi
cycles="$root/cell/tests/fixtures/cycles"
mkdir -p "$out"
printf "| our set (\`--families\`) | main shell soft / hard | insert mold soft / hard | top shell soft / hard | mean |\n|---|---|---|---|---|\n"
for c in "${configs[@]}"; do
    d="$out/$(echo "$c" | tr ',' '_')"
    "${cell[@]}" dataset --out "$d" --seed 2 --train-crops 0 --test-crops 0 --train-overviews 0 \
        --test-overviews 0 --test-feeder "$frames" --families "$c" "${extra[@]}" --quiet > /dev/null
    "$py" scripts/ablation/coverage.py "$d" -- "$cycles/soft" "$cycles/hard" > "$d.md"
    # The "both" share of each Cycles row, in the table's order (part kinds 1-3, soft then hard).
    awk -F'|' -v c="$c" '/cycles\/(soft|hard) / { split($7, a, "/"); v = a[3] + 0; s = s sep v; sep = (n % 2 == 0) ? " / " : " % | "; n++; t += v }
        END { printf "| `%s` | %s %% | %.1f %% |\n", c, s, t / n }' "$d.md"
done
