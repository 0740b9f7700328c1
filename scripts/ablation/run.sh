#!/usr/bin/env bash
# Ablation of the randomisation families (issue 45, item 3) in one go: for each configuration
# (no family, all six, and all six minus one, for each family) a training set made with
# `cell dataset --families`, both networks trained on it (the segmenter and the keypoint net, side
# by side, as training/train_family.sh trains them), `cell eval` on the committed Blender Cycles
# sets (cell/tests/fixtures/cycles/{soft,hard}), and one table of the results. Uses the GPU when
# torch sees one, and needs none. See docs/reference/cycles.md (Randomisation families).
#
# Usage: scripts/ablation/run.sh OUT
#   OUT  a folder for the datasets, models, evaluations and the table (OUT/ablation.md); a second
#        run with the same settings reuses the datasets (they resume) and retrains
# Environment:
#   SIZE          toy (a smoke run: 3 min on 2 CPU cores, nets that detect nothing) or full
#                 (sized for a 16-core GPU machine: datasets about 1 400 CPU-s, 1.5 min a
#                 net in two waves of 4 configurations, evals under a minute: 7-8 min) [full]
#   TRAIN_CROPS   keypoint crops per part of each training set; TRAIN_FEEDER feeder frames;
#   TEST_CROPS, TEST_FEEDER  the trainers' own held-out set (our renderer, no family, seed 2);
#   MINUTES       training budget of each net; SEG_STEPS, KP_EPOCHS their step and epoch caps;
#                 the presets of SIZE give each of these a default
#   CONFIGS       space-separated `cell dataset --families` lists [none all all,-lights ...]
#   JOBS          configurations trained at once [4 with a GPU, 1 without]
#   CATALOG       part catalog [scenarios/parts/usbc.toml]
#   CELL          the cell command [target/release/cell, built if missing]
#   PY            a Python with torch [training/.venv/bin/python, provisioned if missing]
# Every stage's wall and CPU time is printed and appended to OUT/ablation.log.
set -euo pipefail
[ $# -eq 1 ] || { sed -n '2,29p' "$0" >&2; exit 2; }
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
out="$(realpath -m "$1")"
cd "$root"
if [[ -n "${PY:-}" ]]; then py="$(realpath -s "$(type -P "$PY")")" || { echo "no Python at PY=$PY" >&2; exit 2; }; else training/provision.sh >/dev/null; py="$root/training/.venv/bin/python"; fi
if [[ -z "${CELL:-}" ]]; then
    [ -x target/release/cell ] || cargo build --release -q -p cell
    CELL="$root/target/release/cell"
fi
read -r -a cell <<< "$CELL"
catalog="$(realpath -e "${CATALOG:-scenarios/parts/usbc.toml}")"
if "$py" -c 'import torch, sys; sys.exit(0 if torch.cuda.is_available() else 1)'; then
    gpu=1; jobs="${JOBS:-4}"; kp_batch=128; seg_batch=32; threads=2
else
    gpu=0; jobs="${JOBS:-1}"; kp_batch=32; seg_batch=8; threads=1
fi
case "${SIZE:-full}" in
    toy) : "${TRAIN_CROPS:=8}" "${TRAIN_FEEDER:=4}" "${TEST_CROPS:=4}" "${TEST_FEEDER:=2}" \
             "${MINUTES:=0.1}" "${SEG_STEPS:=3}" "${KP_EPOCHS:=1}" ;;
    full) : "${TRAIN_CROPS:=1500}" "${TRAIN_FEEDER:=300}" "${TEST_CROPS:=60}" "${TEST_FEEDER:=20}" \
             "${MINUTES:=1.5}" "${SEG_STEPS:=100000}" "${KP_EPOCHS:=1000}" ;;
    *) echo "run.sh: SIZE must be toy or full, not ${SIZE}" >&2; exit 2 ;;
esac
families=(lights plating plastic textures distractors sensor)
if [[ -n "${CONFIGS:-}" ]]; then
    read -r -a configs <<< "$CONFIGS"
else
    configs=(none all)
    for f in "${families[@]}"; do configs+=("all,-$f"); done
fi
mkdir -p "$out"
log="$out/ablation.log"
echo "$(date -u +%FT%TZ) size ${SIZE:-full}: crops $TRAIN_CROPS/part, feeder $TRAIN_FEEDER, $MINUTES min a net, gpu $gpu, jobs $jobs, $(nproc) cores" >> "$log"
# Wall and CPU seconds of a command, appended to the log with a label.
timed() {
    local label="$1"; shift
    local t0 c0 t1 c1
    t0=$(date +%s.%N); c0=$(awk '{print $14+$15+$16+$17}' /proc/$$/stat)
    "$@"
    t1=$(date +%s.%N); c1=$(awk '{print $14+$15+$16+$17}' /proc/$$/stat)
    awk -v l="$label" -v t0="$t0" -v t1="$t1" -v c="$(( c1 - c0 ))" -v hz="$(getconf CLK_TCK)" \
        'BEGIN { printf "   %s: %.1f s wall, %.1f CPU-s\n", l, t1 - t0, c / hz }' | tee -a "$log"
}
name_of() { case "$1" in none) echo none ;; all) echo all ;; *) echo "no_${1#all,-}" ;; esac; }

echo "== the trainers' held-out set (our renderer, no family, seed 2)"
timed "test set ($TEST_CROPS crops/part, $TEST_FEEDER feeder frames)" \
    "${cell[@]}" dataset --catalog "$catalog" --out "$out/test" --seed 2 --train-crops 0 \
    --test-crops "$TEST_CROPS" --train-overviews 0 --test-overviews 0 --test-feeder "$TEST_FEEDER" --quiet

echo "== training sets (seed 1), one per configuration"
for c in "${configs[@]}"; do
    n="$(name_of "$c")"
    timed "dataset $n ($TRAIN_CROPS crops/part, $TRAIN_FEEDER feeder frames)" \
        "${cell[@]}" dataset --catalog "$catalog" --out "$out/$n/train" --seed 1 --families "$c" \
        --train-crops "$TRAIN_CROPS" --test-crops 0 --train-overviews 0 --test-overviews 0 \
        --train-feeder "$TRAIN_FEEDER" --quiet
done

echo "== both nets per configuration, $MINUTES min each, $jobs configuration(s) at once"
train_config() {
    local n="$1" d="$out/$1"
    mkdir -p "$d/models" "$d/runs"
    local args=(--train "$d/train" --test "$out/test" --catalog "$catalog" --dataset-seed 1
        --threads "$threads" --max-minutes "$MINUTES" --out "$d/models")
    (cd training && "$py" train_segmenter.py "${args[@]}" --steps "$SEG_STEPS" --batch "$seg_batch" \
        --workers 0 --eval-every 500 --checkpoint "$d/runs/segmenter.pt" > "$d/runs/segmenter.log" 2>&1) &
    local seg=$!
    (cd training && "$py" train_keypoints.py "${args[@]}" --epochs "$KP_EPOCHS" --eval-every 5 \
        --batch "$kp_batch" --checkpoint "$d/runs/keypoints.pt" > "$d/runs/keypoints.log" 2>&1) &
    local kp=$!
    local fail=0
    wait "$seg" || { echo "$n: segmenter failed: $d/runs/segmenter.log" >&2; tail -5 "$d/runs/segmenter.log" >&2; fail=1; }
    wait "$kp" || { echo "$n: keypoint net failed: $d/runs/keypoints.log" >&2; tail -5 "$d/runs/keypoints.log" >&2; fail=1; }
    return "$fail"
}
train_all() {
    local pids=() names=() c n fail=0 i
    for c in "${configs[@]}"; do
        n="$(name_of "$c")"
        train_config "$n" & pids+=($!); names+=("$n")
        if (( ${#pids[@]} >= jobs )); then
            wait "${pids[0]}" || fail=1
            pids=("${pids[@]:1}")
        fi
    done
    for i in "${pids[@]}"; do wait "$i" || fail=1; done
    return "$fail"
}
timed "training ${#configs[@]} configurations" train_all

echo "== cell eval on the Cycles sets"
eval_all() {
    local c n look
    for c in "${configs[@]}"; do
        n="$(name_of "$c")"
        for look in soft hard; do
            "${cell[@]}" eval "cell/tests/fixtures/cycles/$look" --models "$out/$n/models" \
                --catalog "$catalog" --max-rms-px 12 --no-finger-check --gallery 0 \
                --out "$out/$n/eval_$look" --quiet > "$out/$n/eval_$look.txt"
        done
    done
}
timed "eval ${#configs[@]} configurations x 2 looks" eval_all
# The committed models as the reference row (trained on the full default randomisation).
eval_committed() {
    local look
    for look in soft hard; do
        "${cell[@]}" eval "cell/tests/fixtures/cycles/$look" --models scenarios/models/usbc \
            --catalog "$catalog" --max-rms-px 12 --no-finger-check --gallery 0 \
            --out "$out/committed/eval_$look" --quiet > /dev/null
    done
}
timed "eval of the committed models x 2 looks" eval_committed

"$py" "$root/scripts/ablation/table.py" "$out" committed "${configs[@]}" | tee "$out/ablation.md"
echo "table: $out/ablation.md; times: $log"
