#!/usr/bin/env bash
# Rebuilds the committed USB-C models from nothing: venv -> datasets (fixed seeds) -> segmenter
# -> keypoint net -> ONNX + manifests in scenarios/models/usbc -> `cell eval` on the test set and
# at the cell's feeder density
# (when that subcommand exists). See training/README.md. Sizes can be overridden by environment:
#   TRAIN_CROPS (per part), TEST_CROPS, TRAIN_FEEDER, TEST_FEEDER, EARLY_CROPS and EARLY_FEEDER
#   (the first cycles' share of the training set), KP_EPOCHS, KP_MINUTES, KP_FT_MINUTES,
#   KP_FT2_MINUTES, SEG_STEPS, SEG_MINUTES, SEG_FT_STEPS, SEG_FT_MINUTES, SEG_FT2_STEPS,
#   SEG_FT2_MINUTES, THREADS (per net), DATA (dataset folder), OUT (model folder), POSED_CROPS
#   (share of the training crop drops holding their part in a stable pose drawn uniformly, 0 for
#   the committed models; use a fresh DATA, the dataset folders resume). The committed
#   models were made with the defaults on 2 busy CPU cores, the two nets trained side by side with
#   one thread each (run the two trainings in parallel by hand to repeat that; this script runs
#   them one after the other). Each net has three cycles: from scratch on the early share, a
#   second at half the learning rate, a third at half the learning rate on the whole set.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
DATA="${DATA:-training/data}"
OUT="${OUT:-scenarios/models/usbc}"
TRAIN_SEED=1
TEST_SEED=2
CELL_FEEDER_SEED=4
TRAIN_CROPS="${TRAIN_CROPS:-4000}"
TEST_CROPS="${TEST_CROPS:-300}"
TRAIN_FEEDER="${TRAIN_FEEDER:-1600}"
POSED_CROPS="${POSED_CROPS:-0}"
EARLY_CROPS="${EARLY_CROPS:-2000}"
EARLY_FEEDER="${EARLY_FEEDER:-400}"
TEST_FEEDER="${TEST_FEEDER:-100}"
KP_EPOCHS="${KP_EPOCHS:-200}"
KP_MINUTES="${KP_MINUTES:-50}"
KP_FT_MINUTES="${KP_FT_MINUTES:-32}"
KP_FT2_MINUTES="${KP_FT2_MINUTES:-60}"
SEG_STEPS="${SEG_STEPS:-3000}"
SEG_MINUTES="${SEG_MINUTES:-40}"
SEG_FT_STEPS="${SEG_FT_STEPS:-2500}"
SEG_FT_MINUTES="${SEG_FT_MINUTES:-14}"
SEG_FT2_STEPS="${SEG_FT2_STEPS:-12000}"
SEG_FT2_MINUTES="${SEG_FT2_MINUTES:-60}"
THREADS="${THREADS:-1}"

training/provision.sh
py="$root/training/.venv/bin/python"
mkdir -p "$DATA" training/runs "$OUT"

echo "== datasets (train seed $TRAIN_SEED, test seed $TEST_SEED)"
# Through cargo: it puts the MuJoCo library the binary links on the library path.
cell() { cargo run --release -q -p cell -- "$@"; }
cell dataset --out "$DATA/usbc_train" --seed "$TRAIN_SEED" --train-crops "$TRAIN_CROPS" \
    --posed-crops "$POSED_CROPS" --test-crops 0 --train-overviews 0 --test-overviews 0 \
    --train-feeder "$TRAIN_FEEDER" --quiet \
    --preview "$DATA/preview_train.png"
cell dataset --out "$DATA/usbc_test" --seed "$TEST_SEED" --train-crops 0 \
    --test-crops "$TEST_CROPS" --train-overviews 0 --test-overviews 0 --test-feeder "$TEST_FEEDER" --quiet
# The cell's own feeder density: parts spread over ±35 mm at the seed's 1.51 m.
cell dataset --out "$DATA/cell_feeder" --seed "$CELL_FEEDER_SEED" --train-crops 0 --test-crops 0 \
    --train-overviews 0 --test-overviews 0 --test-feeder 100 --camera-distance 1.51 --feeder-drop-half 0.035 --quiet

echo "== segmenter (three cycles: from scratch and at half the learning rate on the early share, then at half the learning rate on the whole set with quarter-turned crops)"
seg() { (cd training && "$py" train_segmenter.py --train "$root/$DATA/usbc_train" --test "$root/$DATA/usbc_test" \
    --dataset-seed "$TRAIN_SEED" --threads "$THREADS" "$@"); }
seg --out "$root/training/runs/seg_stage1" --limit "$EARLY_FEEDER" --rotate 0 --steps "$SEG_STEPS" \
    --max-minutes "$SEG_MINUTES" --eval-every 150 --checkpoint "$root/training/runs/segmenter_stage1.pt"
seg --out "$root/training/runs/seg_stage2" --limit "$EARLY_FEEDER" --rotate 0 --steps "$SEG_FT_STEPS" --lr 1e-3 \
    --max-minutes "$SEG_FT_MINUTES" --eval-every 250 --init "$root/training/runs/segmenter_stage1.pt" \
    --checkpoint "$root/training/runs/segmenter_stage2.pt"
seg --out "$root/$OUT" --steps "$SEG_FT2_STEPS" --lr 1e-3 --max-minutes "$SEG_FT2_MINUTES" --eval-every 500 \
    --init "$root/training/runs/segmenter_stage2.pt" --checkpoint "$root/training/runs/segmenter.pt"
cp training/runs/seg_stage1/segmenter_curve.csv "$OUT/segmenter_curve_stage1.csv"
cp training/runs/seg_stage2/segmenter_curve.csv "$OUT/segmenter_curve_stage2.csv"

echo "== keypoint net (three cycles: from scratch and at half the learning rate on the early share, then at half the learning rate on the whole set)"
kp() { (cd training && "$py" train_keypoints.py --train "$root/$DATA/usbc_train" --test "$root/$DATA/usbc_test" \
    --dataset-seed "$TRAIN_SEED" --epochs "$KP_EPOCHS" --threads "$THREADS" "$@"); }
kp --out "$root/training/runs/kp_stage1" --limit "$EARLY_CROPS" --max-minutes "$KP_MINUTES" \
    --checkpoint "$root/training/runs/keypoints_stage1.pt"
kp --out "$root/training/runs/kp_stage2" --limit "$EARLY_CROPS" --lr 1e-3 --max-minutes "$KP_FT_MINUTES" \
    --init "$root/training/runs/keypoints_stage1.pt" --checkpoint "$root/training/runs/keypoints_stage2.pt"
kp --out "$root/$OUT" --limit "$TRAIN_CROPS" --lr 1e-3 --max-minutes "$KP_FT2_MINUTES" \
    --init "$root/training/runs/keypoints_stage2.pt" --checkpoint "$root/training/runs/keypoints.pt"
cp training/runs/kp_stage1/keypoints_curve.csv "$OUT/keypoints_curve_stage1.csv"
cp training/runs/kp_stage2/keypoints_curve.csv "$OUT/keypoints_curve_stage2.csv"

echo "== evaluation"
if cell eval --help >/dev/null 2>&1; then
    cell eval "$DATA/usbc_test" --split test_feeder --models "$OUT" --out "$DATA/eval" \
        || echo "cell eval failed (see above); the models are written"
    cell eval "$DATA/cell_feeder" --models "$OUT" --out "$DATA/eval_cell_feeder" --max-rms-px 12 \
        || echo "cell eval at the cell's feeder density failed (see above)"
else
    echo "skipped: this build of cell has no 'eval' subcommand"
fi
ls -l "$OUT"
