#!/usr/bin/env bash
# The report pages on small inputs, screenshotted at 800 px wide with headless Chromium, each
# checked in the browser to scroll nowhere sideways at that width (no page wider than the
# window, no element with a horizontal scroll bar, no table, picture or plot past the right edge).
#   - the run report of scenarios/usbc_learned.toml, 8 episodes (opens with a capture and its
#     detections)
#   - the run report of scenarios/usbc_nominal.toml, 20 episodes (keypoint noise: opens with the
#     rendered feeder and the perceived poses)
#   - the `cell eval` report of a tiny rendered feeder split (2 frames, `cell dataset`)
# Writes docs/images/report-run-learned.png, report-run-nominal.png, report-eval.png (each the
# top of its page, 800 px wide, palette PNG under 400 KB). Exits 1 if a page scrolls sideways.
# Usage: scripts/report_screenshots/run.sh [--out WORKDIR] [--images DIR] [--height PX]  (about 30 s)
#   --out     where the runs, dataset and reports go (default: a new temporary folder)
#   --images  where the screenshots go (default docs/images)
#   --height  screenshot height in CSS pixels (default 3000)
# Needs: a built `cell` (CELL, default target/release/cell; `cargo build --release -p cell`),
# Chromium (CHROMIUM, default `chromium`; Debian: apt-get install chromium), python3 with PIL.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
die() { echo "report_screenshots: $*" >&2; exit 2; }

work="" images="$repo/docs/images" height=3000
while [ $# -gt 0 ]; do
  case "$1" in
    --out) [ $# -ge 2 ] || die "--out needs a folder"; work="$2"; shift 2 ;;
    --images) [ $# -ge 2 ] || die "--images needs a folder"; images="$2"; shift 2 ;;
    --height) [ $# -ge 2 ] || die "--height needs a number"; height="$2"; shift 2 ;;
    -h|--help) sed -n '2,17p' "${BASH_SOURCE[0]}"; exit 0 ;;
    *) die "unknown argument $1 (see --help)" ;;
  esac
done
[[ "$height" =~ ^[1-9][0-9]*$ ]] || die "--height must be a positive integer, got '$height'"
cell="${CELL:-$repo/target/release/cell}"
chromium="${CHROMIUM:-chromium}"
[ -x "$cell" ] || die "no cell binary at $cell (cargo build --release -p cell, or set CELL)"
command -v "$chromium" >/dev/null || die "no $chromium (apt-get install chromium, or set CHROMIUM)"
python3 -c 'import PIL' 2>/dev/null || die "python3 cannot import PIL (pip install pillow)"
[ -n "$work" ] || work="$(mktemp -d)"
mkdir -p "$work" "$images"
work="$(cd "$work" && pwd)"
images="$(cd "$images" && pwd)"
start=$SECONDS
step() { echo "[$((SECONDS - start)) s] $*"; }

cd "$repo"
step "cell run usbc_learned, 8 episodes"
"$cell" run scenarios/usbc_learned.toml --episodes 8 --pictures 2 --out "$work/runs" --quiet
step "cell run usbc_nominal, 20 episodes"
"$cell" run scenarios/usbc_nominal.toml --episodes 20 --pictures 2 --out "$work/runs" --quiet
if [ ! -d "$work/ds" ]; then
  step "cell dataset: 2 feeder frames"
  "$cell" dataset --out "$work/ds" --seed 5 --train-crops 0 --test-crops 0 \
    --train-overviews 0 --test-overviews 0 --test-feeder 2 --camera-distance 1.5 \
    --supersampling 1 --quiet
fi
step "cell eval"
"$cell" eval "$work/ds" --out "$work/eval" --gallery 4 --quiet >/dev/null

# One Chromium run: a fresh profile, nothing fetched, no GPU.
browse() {
  local profile
  profile="$(mktemp -d)"
  "$chromium" --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
    --disable-background-networking --disable-component-update --disable-sync \
    --hide-scrollbars --force-device-scale-factor=1 --user-data-dir="$profile" "$@" 2>/dev/null
  rm -rf "$profile"
}

failed=0
shoot() { # PAGE NAME
  local page="$1" name="$2" check
  [ -f "$page" ] || die "no page $page"
  # The width check: a copy of the page beside it (same relative links) with a script that
  # measures the laid-out page once everything has loaded and writes the result into the DOM.
  check="$(dirname "$page")/.width-check.html"
  python3 "$repo/scripts/report_screenshots/width_check.py" inject "$page" "$check"
  browse --window-size=800,"$height" --virtual-time-budget=10000 --dump-dom "file://$check" \
    > "$work/$name.dom.html"
  rm -f "$check"
  if ! python3 "$repo/scripts/report_screenshots/width_check.py" verdict "$work/$name.dom.html" "$name"; then
    failed=1
  fi
  browse --window-size=800,"$height" --virtual-time-budget=10000 \
    --screenshot="$work/$name.full.png" "file://$page" >/dev/null
  python3 "$repo/scripts/report_screenshots/width_check.py" shrink "$work/$name.full.png" \
    "$images/$name.png"
}

step "screenshots at 800 px"
shoot "$work/runs/usbc-learned/all/report.html" report-run-learned
shoot "$work/runs/usbc-nominal/all/report.html" report-run-nominal
shoot "$work/eval/eval.html" report-eval
step "done: screenshots in $images, pages in $work"
exit "$failed"
