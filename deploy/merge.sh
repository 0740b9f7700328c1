#!/usr/bin/env bash
# Merges what run-shard.sh wrote under a results root: for each OUT/<scenario>/ holding
# shard-I-of-N folders, `cell merge` writes OUT/<scenario>/merged (episodes.jsonl, summary.json,
# report.html). `cell merge` refuses a missing shard or episode (so a merge after a failed shard
# fails too) and shards of another scenario file, seed or split.
#
# Usage: merge.sh OUT [cell merge options...]
# CELL_BIN: the cell binary (default: `cell` on PATH).
set -euo pipefail
[ $# -ge 1 ] || {
  echo "merge.sh: usage: merge.sh OUT [cell merge options...]" >&2
  exit 2
}
out=$1
shift
cell=${CELL_BIN:-cell}
merged=0
for dir in "$out"/*/; do
  dir=${dir%/}
  compgen -G "$dir/shard-*-of-*" >/dev/null || continue
  "$cell" merge "$dir" --out "$dir/merged" "$@"
  merged=$((merged + 1))
done
[ "$merged" -gt 0 ] || {
  echo "merge.sh: no shard folders (OUT/<scenario>/shard-I-of-N) under $out" >&2
  exit 1
}
