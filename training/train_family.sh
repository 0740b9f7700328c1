#!/usr/bin/env bash
# A part family's learned cell in one command: datasets of the catalog (fixed seeds) -> the
# segmenter and the keypoint net trained side by side -> ONNX + manifests in
# scenarios/models/NAME -> `cell eval` on the test feeder frames and at a cell's feeder density.
# The segmenter sees every frame at one table scale (--fixed-scale), the scale the cell shows it.
# Uses the GPU when torch sees one, and needs none. See docs/guides/perception.md (A new part family).
#
# Usage: training/train_family.sh CATALOG [NAME]
#   CATALOG  a prepared part catalog (`cell parts prepare CATALOG` first: keypoints, stable poses)
#   NAME     the model folder's name under scenarios/models [the catalog's `name`]
# Environment (defaults: CPU [GPU]):
#   MINUTES       training budget of each net [130] [5]; the two train at once
#   TRAIN_CROPS   keypoint crops per part [4000] [4000]; TEST_CROPS [300]
#   TRAIN_FEEDER  feeder frames [1600] [1200]; TEST_FEEDER [100]; CELL_FEEDER [100] (at the
#                 cell's density: parts spread over +-35 mm at 1.51 m)
#   FEEDER_DROP_HALF  half-size (m) of the square the training and test feeder frames' parts
#                 drop into [cell dataset's 0.015: a heap of USB-C-sized parts]; larger parts or
#                 more of them want more room (a pile is slow to drop and unlike a shaken feeder)
#   INIT          a folder with segmenter.pt and keypoints.pt to start both nets from (a further
#                 training cycle, or a changed catalog of the same family) [none: from scratch]
#   PRETRAINED    a folder with another part family's segmenter.pt and keypoints.pt to start both
#                 nets from (their layers copied, each new part's from the mean of its parts)
#   SCENARIO      a scenario of the family for `cell eval`'s finger-room check [none: not checked]
#   DATA, OUT     dataset folder [training/data/NAME], model folder [scenarios/models/NAME]
#   CELL          the cell command ["cargo run --release -q -p cell --"], e.g. a prebuilt binary
#   PY            a Python with torch [training/.venv/bin/python, provisioned if missing]
# Every stage's wall time is printed and appended to OUT/train_family.log. The datasets resume if
# interrupted; a second run with the same settings reuses them.
set -euo pipefail
[ $# -ge 1 ] && [ $# -le 2 ] || { sed -n '2,28p' "$0" >&2; exit 2; }
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
catalog="$(realpath -e "$1")" || { echo "train_family: no catalog at $1" >&2; exit 2; }
cd "$root"
if [[ -n "${PY:-}" ]]; then py="$(realpath -s "$(type -P "$PY")")" || { echo "no Python at PY=$PY" >&2; exit 2; }; else training/provision.sh; py="$root/training/.venv/bin/python"; fi
name="${2:-$(cd training && "$py" -c 'import catalog, sys; print(catalog.family(sys.argv[1]))' "$catalog")}"
parts="$(cd training && "$py" -c 'import catalog, sys; print(",".join(catalog.assembled_parts(sys.argv[1])))' "$catalog")"
DATA="$(realpath -m "${DATA:-training/data/$name}")"
OUT="$(realpath -m "${OUT:-scenarios/models/$name}")"
read -r -a cell <<< "${CELL:-cargo run --release -q -p cell --}"
if "$py" -c 'import torch, sys; sys.exit(0 if torch.cuda.is_available() else 1)'; then
    # Sized for the 20-minute goal: the six NIST pegs on one H200 with 16 cores took 13.5 min up to
    # the keypoint net's closing evaluation (datasets 337 s; scenarios/models/nist_pegs/README.md).
    gpu=1; MINUTES="${MINUTES:-5}"; TRAIN_CROPS="${TRAIN_CROPS:-4000}"; TRAIN_FEEDER="${TRAIN_FEEDER:-1200}"
    threads=4; kp_batch=128; seg_batch=32; seg_workers=8
else
    gpu=0; MINUTES="${MINUTES:-130}"; TRAIN_CROPS="${TRAIN_CROPS:-4000}"; TRAIN_FEEDER="${TRAIN_FEEDER:-1600}"
    threads=1; kp_batch=32; seg_batch=8; seg_workers=0
fi
TEST_CROPS="${TEST_CROPS:-300}"
TEST_FEEDER="${TEST_FEEDER:-100}"
CELL_FEEDER="${CELL_FEEDER:-100}"
heap=()
[ -n "${FEEDER_DROP_HALF:-}" ] && heap=(--feeder-drop-half "$FEEDER_DROP_HALF")
seg_start=(); kp_start=()
[ -n "${INIT:-}" ] && [ -n "${PRETRAINED:-}" ] && { echo "train_family: give INIT or PRETRAINED, not both" >&2; exit 2; }
start="${INIT:-${PRETRAINED:-}}"
if [ -n "$start" ]; then
    flag=--init; var=INIT; [ -n "${PRETRAINED:-}" ] && { flag=--pretrained; var=PRETRAINED; }
    for net in segmenter keypoints; do
        [ -f "$start/$net.pt" ] || { echo "train_family: $var=$start has no $net.pt" >&2; exit 2; }
    done
    seg_start=("$flag" "$(realpath "$start/segmenter.pt")"); kp_start=("$flag" "$(realpath "$start/keypoints.pt")")
fi
mkdir -p "$DATA" "$OUT"
log="$OUT/train_family.log"
t_all=$(date +%s)
stage() { echo "== $1 ($(date -u +%H:%M:%S))"; t_stage=$(date +%s); }
done_stage() { local s=$(( $(date +%s) - t_stage )); echo "   $1: ${s} s" | tee -a "$log"; }
echo "$(date -u +%FT%TZ) $name from $catalog (parts $parts; gpu $gpu; $MINUTES min per net${start:+; from $start})" >> "$log"

stage "datasets of $parts (train seed 1, test seed 2, cell density seed 4)"
"${cell[@]}" dataset --catalog "$catalog" --out "$DATA/train" --seed 1 --train-crops "$TRAIN_CROPS" \
    --test-crops 0 --train-overviews 0 --test-overviews 0 --train-feeder "$TRAIN_FEEDER" "${heap[@]}" --quiet
"${cell[@]}" dataset --catalog "$catalog" --out "$DATA/test" --seed 2 --train-crops 0 \
    --test-crops "$TEST_CROPS" --train-overviews 0 --test-overviews 0 --test-feeder "$TEST_FEEDER" "${heap[@]}" --quiet
"${cell[@]}" dataset --catalog "$catalog" --out "$DATA/cell_feeder" --seed 4 --train-crops 0 --test-crops 0 \
    --train-overviews 0 --test-overviews 0 --test-feeder "$CELL_FEEDER" --camera-distance 1.51 --feeder-drop-half 0.035 --quiet
done_stage datasets

stage "both nets side by side, $MINUTES min each"
runs="$DATA/runs"
mkdir -p "$runs"
train() { (cd training && "$py" "$@" --train "$DATA/train" --test "$DATA/test" --catalog "$catalog" \
    --dataset-seed 1 --threads "$threads" --max-minutes "$MINUTES" --out "$OUT"); }
train train_segmenter.py --steps 100000 --batch "$seg_batch" --workers "$seg_workers" --eval-every 500 --fixed-scale \
    --checkpoint "$runs/segmenter.pt" "${seg_start[@]}" > "$runs/segmenter.log" 2>&1 &
seg=$!
train train_keypoints.py --epochs 1000 --eval-every 5 --batch "$kp_batch" \
    --checkpoint "$runs/keypoints.pt" "${kp_start[@]}" > "$runs/keypoints.log" 2>&1 &
kp=$!
fail=0
wait "$seg" || { echo "segmenter training failed: $runs/segmenter.log" >&2; tail -5 "$runs/segmenter.log" >&2; fail=1; }
wait "$kp" || { echo "keypoint training failed: $runs/keypoints.log" >&2; tail -5 "$runs/keypoints.log" >&2; fail=1; }
[ "$fail" = 0 ] || exit 1
done_stage training

stage "cell eval"
finger=(--no-finger-check)
[ -n "${SCENARIO:-}" ] && finger=(--scenario "$SCENARIO")
"${cell[@]}" eval "$DATA/test" --split test_feeder --models "$OUT" --catalog "$catalog" \
    --out "$DATA/eval" "${finger[@]}" --quiet | tee "$OUT/eval_test.txt"
"${cell[@]}" eval "$DATA/cell_feeder" --models "$OUT" --catalog "$catalog" --out "$DATA/eval_cell_feeder" \
    --max-rms-px 12 "${finger[@]}" --quiet | tee "$OUT/eval_cell_feeder.txt"
done_stage eval
echo "   total: $(( $(date +%s) - t_all )) s" | tee -a "$log"
echo "models in $OUT; point a learned scenario's [perception] models at it (docs/guides/perception.md)"
