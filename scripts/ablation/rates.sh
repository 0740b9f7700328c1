#!/usr/bin/env bash
# Dataset factory rates per randomisation family: keypoint crops and feeder frames per CPU-second
# of `cell dataset --families F` for no family, each family alone and all six, one worker thread
# (so wall and CPU time agree on an idle host; CPU time is what is reported). Sizes a run of
# scripts/ablation/run.sh: its datasets cost crops / rate + frames / rate CPU-seconds.
#
# Usage: scripts/ablation/rates.sh OUT [CROPS_PER_PART] [FRAMES]   [defaults 20 and 4]
# Environment: CELL (the cell command) [target/release/cell], CATALOG [scenarios/parts/usbc.toml]
set -euo pipefail
[ $# -ge 1 ] && [ $# -le 3 ] || { sed -n '2,9p' "$0" >&2; exit 2; }
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
out="$(realpath -m "$1")"
crops="${2:-20}"
frames="${3:-4}"
cd "$root"
read -r -a cell <<< "${CELL:-$root/target/release/cell}"
catalog="${CATALOG:-scenarios/parts/usbc.toml}"
parts=$(grep -c '^\[\[part\]\]' "$catalog")
fixtures=$(grep -c '^role *= *"fixture"' "$catalog" || true)
n_parts=$(( parts - fixtures ))
rm -rf "$out"
mkdir -p "$out"
# CPU-seconds (user + system) of one `cell dataset` run.
cpu() {
    /usr/bin/time -f "%U %S" -o "$out/time" "${cell[@]}" dataset --catalog "$catalog" --threads 1 \
        --quiet --train-overviews 0 --test-overviews 0 --test-crops 0 "$@" > /dev/null
    awk '{ print $1 + $2 }' "$out/time"
}
printf "| families | crops / CPU-s | feeder frames / CPU-s |\n|---|---|---|\n"
for f in none lights plating plastic textures distractors sensor all; do
    c=$(cpu --out "$out/$f-crops" --seed 1 --families "$f" --train-crops "$crops" --train-feeder 0)
    r=$(cpu --out "$out/$f-feeder" --seed 1 --families "$f" --train-crops 0 --train-feeder "$frames")
    awk -v f="$f" -v n="$(( crops * n_parts ))" -v c="$c" -v m="$frames" -v r="$r" \
        'BEGIN { printf "| `%s` | %.1f | %.2f |\n", f, n / c, m / r }'
done
