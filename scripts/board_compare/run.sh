#!/usr/bin/env bash
# Side by side on the same rendered boards: our board detection and pose (`cell board-study`),
# OpenCV's ArUco detector with DICT_APRILTAG_36h11 + corner refinement + solvePnP (SQPnP, then
# refineLM), and the pure-Rust `aprilgrid` crate. Not part of the test suite or the workspace
# build (OpenCV comes from PyPI, aprilgrid is a standalone cargo project).
# Usage: scripts/board_compare/run.sh [opencv|aprilgrid|all] [IMAGES] [DIR]
#   renders IMAGES boards (default 100) with `cell board-study --save DIR --out DIR/ours.json`
#   unless DIR (default target/board_compare) already holds ours.json.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
what="${1:-all}"
images="${2:-100}"
dir="${3:-$repo/target/board_compare}"
if [ ! -f "$dir/ours.json" ]; then
  (cd "$repo" && cargo run --release -q -p cell -- board-study --images "$images" --save "$dir" \
    --out "$dir/ours.json")
fi
if [ "$what" = opencv ] || [ "$what" = all ]; then
  py=$("$repo/scripts/pinned_venv.sh" "$repo/target/venv-board-compare" "import cv2, numpy" \
    "opencv-python-headless==4.14.0.94" "numpy<3")
  "$py" "$repo/scripts/board_compare/opencv.py" "$dir"
fi
if [ "$what" = aprilgrid ] || [ "$what" = all ]; then
  (cd "$repo/scripts/board_compare/aprilgrid" &&
    CARGO_TARGET_DIR="$repo/target/board_compare_aprilgrid" cargo run --release -q -- "$dir")
fi
