#!/usr/bin/env bash
# Rebuilds the USB-C models on one GPU in about ten minutes: larger datasets (fixed seeds) -> the
# segmenter and the keypoint net trained side by side, one cycle each -> ONNX + manifests in OUT.
# The CPU recipe is training/build_models.sh; this one differs only in sizes, batches and budgets.
#
# Environment (defaults in brackets):
#   STAGES       "data train" (either or both)
#   CELL         the cell command ["cargo run --release -q -p cell --"], e.g. a prebuilt binary
#   PY           the Python with torch [training/.venv/bin/python, provisioned if missing]
#   DATA, OUT    dataset folder [training/data], model folder [scenarios/models/usbc]
#   TRAIN_CROPS (per part) [6000], TEST_CROPS [300], TRAIN_FEEDER [2400], TEST_FEEDER [100]
#   MINUTES      training budget of each net [5]
#   INIT         folder with keypoints.pt and segmenter.pt to start from [none: from scratch]
#   KP_LR, SEG_LR  peak learning rates [2e-3 from scratch, 1e-3 from INIT]
#   KP_BATCH [128], SEG_BATCH [32], WORKERS (segmenter batch processes) [6]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
STAGES="${STAGES:-data train}"
DATA="$(realpath -m "${DATA:-training/data}")"
OUT="$(realpath -m "${OUT:-scenarios/models/usbc}")"
TRAIN_SEED=1
TEST_SEED=2
TRAIN_CROPS="${TRAIN_CROPS:-6000}"
TEST_CROPS="${TEST_CROPS:-300}"
TRAIN_FEEDER="${TRAIN_FEEDER:-2400}"
TEST_FEEDER="${TEST_FEEDER:-100}"
MINUTES="${MINUTES:-5}"
INIT="${INIT:+$(realpath "$INIT")}"
default_lr=2e-3
[[ -n "$INIT" ]] && default_lr=1e-3
KP_LR="${KP_LR:-$default_lr}"
SEG_LR="${SEG_LR:-$default_lr}"
KP_BATCH="${KP_BATCH:-128}"
SEG_BATCH="${SEG_BATCH:-32}"
WORKERS="${WORKERS:-6}"

if [[ " $STAGES " == *" data "* ]]; then
    read -r -a cell <<< "${CELL:-cargo run --release -q -p cell --}"
    echo "== datasets (train seed $TRAIN_SEED, test seed $TEST_SEED), $(date +%T)"
    "${cell[@]}" dataset --out "$DATA/usbc_train" --seed "$TRAIN_SEED" --train-crops "$TRAIN_CROPS" \
        --test-crops 0 --train-overviews 0 --test-overviews 0 --train-feeder "$TRAIN_FEEDER" --quiet
    "${cell[@]}" dataset --out "$DATA/usbc_test" --seed "$TEST_SEED" --train-crops 0 \
        --test-crops "$TEST_CROPS" --train-overviews 0 --test-overviews 0 --test-feeder "$TEST_FEEDER" --quiet
fi

if [[ " $STAGES " == *" train "* ]]; then
    if [[ -z "${PY:-}" ]]; then
        training/provision.sh
        PY="$root/training/.venv/bin/python"
    fi
    mkdir -p "$OUT"
    init() { [[ -n "$INIT" ]] && echo --init "$INIT/$1.pt"; true; }
    common=(--train "$DATA/usbc_train" --test "$DATA/usbc_test" --dataset-seed "$TRAIN_SEED" --out "$OUT"
        --max-minutes "$MINUTES" --threads 4)
    echo "== segmenter and keypoint net side by side, $MINUTES min each, $(date +%T)"
    cd training
    # shellcheck disable=SC2046
    "$PY" train_segmenter.py "${common[@]}" --steps 1000000 --batch "$SEG_BATCH" --lr "$SEG_LR" \
        --workers "$WORKERS" --eval-every 2000 $(init segmenter) > "$OUT/segmenter.log" 2>&1 &
    seg=$!
    # shellcheck disable=SC2046
    "$PY" train_keypoints.py "${common[@]}" --epochs 100000 --batch "$KP_BATCH" --lr "$KP_LR" \
        --eval-every 10 $(init keypoints) > "$OUT/keypoints.log" 2>&1 &
    kp=$!
    status=0
    wait "$seg" || { status=1; echo "segmenter failed:"; tail -20 "$OUT/segmenter.log"; }
    wait "$kp" || { status=1; echo "keypoint net failed:"; tail -20 "$OUT/keypoints.log"; }
    tail -n 4 "$OUT/segmenter.log" "$OUT/keypoints.log"
    echo "== done, $(date +%T)"
    exit "$status"
fi
