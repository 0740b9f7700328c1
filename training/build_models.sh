#!/usr/bin/env bash
# Rebuilds the committed USB-C models from nothing: venv -> datasets (fixed seeds) -> segmenter
# -> keypoint net -> ONNX + manifests in scenarios/models/usbc -> `cell eval` on the test set
# (when that subcommand exists). See training/README.md. Sizes can be overridden by environment:
#   TRAIN_CROPS (per part), TEST_CROPS, TRAIN_FEEDER, TEST_FEEDER, KP_EPOCHS, KP_MINUTES, KP_FT_MINUTES,
#   SEG_STEPS, SEG_MINUTES, SEG_FT_STEPS, SEG_FT_MINUTES, THREADS (per net), DATA (dataset
#   folder), OUT (model folder). The committed models were made with the defaults on 2 busy CPU
#   cores, the two nets trained side by side with one thread each (run the two trainings in
#   parallel by hand to repeat that; this script runs them one after the other).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
DATA="${DATA:-training/data}"
OUT="${OUT:-scenarios/models/usbc}"
TRAIN_SEED=1
TEST_SEED=2
TRAIN_CROPS="${TRAIN_CROPS:-2000}"
TEST_CROPS="${TEST_CROPS:-300}"
TRAIN_FEEDER="${TRAIN_FEEDER:-400}"
TEST_FEEDER="${TEST_FEEDER:-100}"
KP_EPOCHS="${KP_EPOCHS:-200}"
KP_MINUTES="${KP_MINUTES:-50}"
KP_FT_MINUTES="${KP_FT_MINUTES:-32}"
SEG_STEPS="${SEG_STEPS:-3000}"
SEG_MINUTES="${SEG_MINUTES:-40}"
SEG_FT_STEPS="${SEG_FT_STEPS:-2500}"
SEG_FT_MINUTES="${SEG_FT_MINUTES:-14}"
THREADS="${THREADS:-1}"

training/provision.sh
py="$root/training/.venv/bin/python"
mkdir -p "$DATA" training/runs "$OUT"

echo "== datasets (train seed $TRAIN_SEED, test seed $TEST_SEED)"
# Through cargo: it puts the MuJoCo library the binary links on the library path.
cell() { cargo run --release -q -p cell -- "$@"; }
cell dataset --out "$DATA/usbc_train" --seed "$TRAIN_SEED" --train-crops "$TRAIN_CROPS" \
    --test-crops 0 --train-overviews 0 --test-overviews 0 --train-feeder "$TRAIN_FEEDER" --quiet \
    --preview "$DATA/preview_train.png"
cell dataset --out "$DATA/usbc_test" --seed "$TEST_SEED" --train-crops 0 \
    --test-crops "$TEST_CROPS" --train-overviews 0 --test-overviews 0 --test-feeder "$TEST_FEEDER" --quiet

echo "== segmenter (two stages: from scratch, then a fine-tuning cycle at half the learning rate)"
(cd training && "$py" train_segmenter.py --train "$root/$DATA/usbc_train" --test "$root/$DATA/usbc_test" \
    --out "$root/training/runs/seg_stage1" --dataset-seed "$TRAIN_SEED" --steps "$SEG_STEPS" \
    --max-minutes "$SEG_MINUTES" --eval-every 150 --threads "$THREADS" \
    --checkpoint "$root/training/runs/segmenter_stage1.pt")
(cd training && "$py" train_segmenter.py --train "$root/$DATA/usbc_train" --test "$root/$DATA/usbc_test" \
    --out "$root/$OUT" --dataset-seed "$TRAIN_SEED" --steps "$SEG_FT_STEPS" --lr 1e-3 \
    --max-minutes "$SEG_FT_MINUTES" --eval-every 250 --threads "$THREADS" \
    --init "$root/training/runs/segmenter_stage1.pt" --checkpoint "$root/training/runs/segmenter.pt")
cp training/runs/seg_stage1/segmenter_curve.csv "$OUT/segmenter_curve_stage1.csv"

echo "== keypoint net (two cycles: from scratch, then a second cycle at half the learning rate)"
(cd training && "$py" train_keypoints.py --train "$root/$DATA/usbc_train" --test "$root/$DATA/usbc_test" \
    --out "$root/training/runs/kp_stage1" --dataset-seed "$TRAIN_SEED" --epochs "$KP_EPOCHS" --limit "$TRAIN_CROPS" \
    --max-minutes "$KP_MINUTES" --threads "$THREADS" --checkpoint "$root/training/runs/keypoints_stage1.pt")
(cd training && "$py" train_keypoints.py --train "$root/$DATA/usbc_train" --test "$root/$DATA/usbc_test" \
    --out "$root/$OUT" --dataset-seed "$TRAIN_SEED" --epochs "$KP_EPOCHS" --limit "$TRAIN_CROPS" --lr 1e-3 \
    --max-minutes "$KP_FT_MINUTES" --threads "$THREADS" --init "$root/training/runs/keypoints_stage1.pt" \
    --checkpoint "$root/training/runs/keypoints.pt")
cp training/runs/kp_stage1/keypoints_curve.csv "$OUT/keypoints_curve_stage1.csv"

echo "== evaluation"
if cell eval --help >/dev/null 2>&1; then
    cell eval "$DATA/usbc_test" --split test_feeder --models "$OUT" --out "$DATA/eval" \
        || echo "cell eval failed (see above); the models are written"
else
    echo "skipped: this build of cell has no 'eval' subcommand"
fi
ls -l "$OUT"
