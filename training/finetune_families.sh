#!/usr/bin/env bash
# A further training cycle of the USB-C pair on frames with the randomisation families (issue 45):
# the pair in FROM fine-tuned on 2 CPU cores, as the committed pair in scenarios/models/usbc was
# made (2026-11-30, from the pair of commit 73fdd80). Datasets (fixed seeds; the families set holds the plain set's scenes in other
# looks) -> the segmenter and the keypoint net side by side on the families set, one thread each
# -> the segmenter again on the families and plain frames together, at half the learning rate,
# so that it keeps our renderer's plain look -> the keypoint net likewise on the families and
# plain crops -> ONNX + manifests in OUT -> `cell eval` on the
# committed Blender Cycles sets and on our own test and cell-density frames. Uses the GPU when
# torch sees one (then the two nets also share it in the second stage, and the sizes fit one
# 15-minute lease of a GPU machine with 16 cores), and needs none. See training/README.md and
# docs/reference/cycles.md.
#
# Usage: training/finetune_families.sh FROM
#   FROM  a folder with the pair's segmenter.pt and keypoints.pt to start from (the committed
#         pair started from scenarios/models/usbc as of commit 73fdd80)
# Environment (defaults in brackets):
#   FAMILIES      `cell dataset --families` of the families set [all]
#   MINUTES       budget of each net on the families set [60] [GPU: 4]; MIX_MINUTES each net's
#                 further cycle on both looks [30, one net after the other] [GPU: 2, side by side]
#   TRAIN_CROPS (per part) [4000], TRAIN_FEEDER [1600], TEST_CROPS [300], TEST_FEEDER [100]
#   DATA, OUT     dataset folder [training/data], model folder [scenarios/models/usbc_next];
#                 the scenarios' pair (scenarios/models/usbc) is replaced only by naming it here
#   CELL          the cell command ["cargo run --release -q -p cell --"], e.g. a prebuilt binary
#   PY            a Python with torch [training/.venv/bin/python, provisioned if missing]
set -euo pipefail
[ $# -eq 1 ] || { sed -n '2,25p' "$0" >&2; exit 2; }
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
from="$(realpath -e "$1")" || { echo "finetune_families: no folder at $1" >&2; exit 2; }
for net in segmenter keypoints; do
    [ -f "$from/$net.pt" ] || { echo "finetune_families: $from has no $net.pt" >&2; exit 2; }
done
cd "$root"
FAMILIES="${FAMILIES:-all}"
TRAIN_CROPS="${TRAIN_CROPS:-4000}"
TRAIN_FEEDER="${TRAIN_FEEDER:-1600}"
TEST_CROPS="${TEST_CROPS:-300}"
TEST_FEEDER="${TEST_FEEDER:-100}"
DATA="$(realpath -m "${DATA:-training/data}")"
OUT="$(realpath -m "${OUT:-scenarios/models/usbc_next}")"
read -r -a cell <<< "${CELL:-cargo run --release -q -p cell --}"
if [[ -z "${PY:-}" ]]; then
    training/provision.sh
    PY="$root/training/.venv/bin/python"
fi
if "$PY" -c 'import torch, sys; sys.exit(0 if torch.cuda.is_available() else 1)'; then
    # The batches of train_family.sh's GPU run (scenarios/models/nist_pegs/README.md). The USB-C
    # datasets cost less than the NIST pegs' (frames about an eighth, crops under half).
    gpu=1; MINUTES="${MINUTES:-4}"; MIX_MINUTES="${MIX_MINUTES:-2}"
    threads=4; mix_threads=4; kp_batch=128; seg_batch=32; seg_workers=8
else
    gpu=0; MINUTES="${MINUTES:-60}"; MIX_MINUTES="${MIX_MINUTES:-30}"
    threads=1; mix_threads=2; kp_batch=32; seg_batch=8; seg_workers=0
fi
runs="$root/training/runs/finetune_families"
mkdir -p "$DATA" "$OUT" "$runs"

echo "== datasets, $(date +%T)"
sets=(--train-overviews 0 --test-overviews 0 --quiet)
"${cell[@]}" dataset --out "$DATA/usbc_families" --seed 1 --families "$FAMILIES" --train-crops "$TRAIN_CROPS" \
    --test-crops 0 --train-feeder "$TRAIN_FEEDER" "${sets[@]}"
"${cell[@]}" dataset --out "$DATA/usbc_train" --seed 1 --train-crops 0 --test-crops 0 \
    --train-feeder "$TRAIN_FEEDER" "${sets[@]}"
"${cell[@]}" dataset --out "$DATA/usbc_plain_crops" --seed 1 --train-crops "$TRAIN_CROPS" --test-crops 0 \
    --posed-crops 0.3 "${sets[@]}"
"${cell[@]}" dataset --out "$DATA/usbc_test" --seed 2 --train-crops 0 --test-crops "$TEST_CROPS" \
    --test-feeder "$TEST_FEEDER" "${sets[@]}"
"${cell[@]}" dataset --out "$DATA/cell_feeder" --seed 4 --train-crops 0 --test-crops 0 --test-feeder 100 \
    --camera-distance 1.51 --feeder-drop-half 0.035 "${sets[@]}"
echo "== segmenter and keypoint net side by side on the families set, $MINUTES min each, $(date +%T)"
common=(--test "$DATA/usbc_test" --dataset-seed 1)
seg_args=(--steps 1000000 --batch "$seg_batch" --workers "$seg_workers" --eval-every 500)
kp_args=(--epochs 100000 --batch "$kp_batch")
# Each net's run: NAME LOG ARGS...; fails with the log's tail.
net() {
    local name="$1" log="$2"; shift 2
    "$PY" "train_$name.py" "${common[@]}" "$@" > "$log" 2>&1 || { echo "$name failed:"; tail -20 "$log"; return 1; }
}
pushd training > /dev/null
net segmenter "$runs/segmenter.log" "${seg_args[@]}" --threads "$threads" --train "$DATA/usbc_families" \
    --out "$runs/segmenter" --lr 1e-3 --max-minutes "$MINUTES" --init "$from/segmenter.pt" &
seg=$!
net keypoints "$runs/keypoints.log" "${kp_args[@]}" --threads "$threads" --train "$DATA/usbc_families" \
    --out "$runs/keypoints" --lr 1e-3 --max-minutes "$MINUTES" --init "$from/keypoints.pt" &
kp=$!
status=0
wait "$seg" || status=1
wait "$kp" || status=1
[[ "$status" == 0 ]] || exit "$status"

echo "== both nets on the families and our plain look, $MIX_MINUTES min each, $(date +%T)"
mix_segmenter() {
    net segmenter "$runs/segmenter_mix.log" "${seg_args[@]}" --threads "$mix_threads" \
        --train "$DATA/usbc_families:$DATA/usbc_train" --out "$OUT" --lr 5e-4 --max-minutes "$MIX_MINUTES" \
        --init "$runs/segmenter/segmenter.pt"
}
# On a GPU the two nets share it; on CPU one runs after the other, each on both cores.
seg=
if [[ "$gpu" == 1 ]]; then mix_segmenter & seg=$!; else mix_segmenter || exit 1; fi
net keypoints "$runs/keypoints_mix.log" "${kp_args[@]}" --threads "$mix_threads" \
    --train "$DATA/usbc_families:$DATA/usbc_plain_crops" --out "$OUT" --lr 5e-4 --max-minutes "$MIX_MINUTES" \
    --init "$runs/keypoints/keypoints.pt" || status=1
[[ -z "$seg" ]] || wait "$seg" || status=1
[[ "$status" == 0 ]] || exit "$status"
cp "$runs/segmenter/segmenter_curve.csv" "$OUT/segmenter_curve_families.csv"
cp "$runs/keypoints/keypoints_curve.csv" "$OUT/keypoints_curve_families.csv"
popd > /dev/null

echo "== cell eval, $(date +%T)"
for look in soft hard; do
    "${cell[@]}" eval "cell/tests/fixtures/cycles/$look" --models "$OUT" --max-rms-px 12 \
        --out "$DATA/eval_cycles_$look" --quiet
done
"${cell[@]}" eval "$DATA/usbc_test" --split test_feeder --models "$OUT" --out "$DATA/eval" --max-rms-px 12 --quiet
"${cell[@]}" eval "$DATA/cell_feeder" --models "$OUT" --out "$DATA/eval_cell_feeder" --max-rms-px 12 --quiet
echo "== done, $(date +%T)"
