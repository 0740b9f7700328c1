#!/usr/bin/env bash
# One shard of a sharded `cell run`, from the task index a scheduler hands its array task. This is
# the only place that turns a scheduler's index into `--shard I/N`; shards count from 1.
#
# Usage: run-shard.sh SCENARIO OUT [cell run options...]
#   Runs `$CELL_BIN run SCENARIO --shard I/N --out OUT [options...]`: results go to
#   OUT/<scenario name>/shard-I-of-N/episodes.jsonl, and `merge.sh OUT` combines them.
#
# Where I and N come from (exactly one of these must be present):
#   SLURM job array (sbatch --array=MIN-MAX, step 1): SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_MIN
#     and SLURM_ARRAY_TASK_COUNT (or SLURM_ARRAY_TASK_MAX): I = ID - MIN + 1, N = COUNT.
#   Kubernetes Indexed Job: JOB_COMPLETION_INDEX (0 to completions - 1) and CELL_SHARDS, which the
#     Job sets equal to its `completions`: I = JOB_COMPLETION_INDEX + 1, N = CELL_SHARDS.
#   CELL_SHARDS, when set beside a SLURM array, must equal its task count.
# CELL_BIN: the cell binary (default: `cell` on PATH).
set -euo pipefail

die() {
  echo "run-shard.sh: $*" >&2
  exit 2
}

# A whole number in decimal (leading zeros allowed, read as decimal), or refuse.
number() {
  local name=$1 value=$2
  [[ $value =~ ^[0-9]+$ ]] || die "$name is '$value', not a whole number"
  echo $((10#$value))
}

[ $# -ge 2 ] || die "usage: run-shard.sh SCENARIO OUT [cell run options...] (in a SLURM array task or a Kubernetes Indexed Job)"
scenario=$1
out=$2
shift 2
for arg in "$@"; do
  case $arg in
    --shard | --shard=* | --out | --out=*) die "$arg is this script's to set; pass SCENARIO OUT and other options only" ;;
  esac
done

slurm=${SLURM_ARRAY_TASK_ID:+yes}
k8s=${JOB_COMPLETION_INDEX:+yes}
if [ -n "$slurm" ] && [ -n "$k8s" ]; then
  die "both SLURM_ARRAY_TASK_ID ($SLURM_ARRAY_TASK_ID) and JOB_COMPLETION_INDEX ($JOB_COMPLETION_INDEX) are set; refusing to guess which scheduler runs this task"
elif [ -n "$slurm" ]; then
  id=$(number SLURM_ARRAY_TASK_ID "$SLURM_ARRAY_TASK_ID")
  [ -n "${SLURM_ARRAY_TASK_MIN:-}" ] ||
    die "SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_MIN is not (SLURM sets both for a job array)"
  min=$(number SLURM_ARRAY_TASK_MIN "$SLURM_ARRAY_TASK_MIN")
  step=${SLURM_ARRAY_TASK_STEP:-1}
  step=$(number SLURM_ARRAY_TASK_STEP "$step")
  [ "$step" = 1 ] || die "SLURM_ARRAY_TASK_STEP is $step: shards need a contiguous array (--array=1-N)"
  count=${SLURM_ARRAY_TASK_COUNT:-}
  max=${SLURM_ARRAY_TASK_MAX:-}
  [ -n "$count" ] || [ -n "$max" ] ||
    die "SLURM_ARRAY_TASK_ID is set but neither SLURM_ARRAY_TASK_COUNT nor SLURM_ARRAY_TASK_MAX is"
  [ -z "$count" ] || count=$(number SLURM_ARRAY_TASK_COUNT "$count")
  [ -z "$max" ] || max=$(number SLURM_ARRAY_TASK_MAX "$max")
  if [ -n "$max" ]; then
    [ "$max" -ge "$min" ] || die "SLURM_ARRAY_TASK_MAX ($max) is below SLURM_ARRAY_TASK_MIN ($min)"
    span=$((max - min + 1))
    [ -z "$count" ] || [ "$count" = "$span" ] ||
      die "SLURM_ARRAY_TASK_COUNT is $count but the array runs $min-$max ($span tasks): shards need a contiguous array (--array=1-N)"
    count=$span
  fi
  shards=$count
  index=$((id - min + 1))
  if [ "$id" -lt "$min" ] || [ "$index" -gt "$shards" ]; then
    die "SLURM_ARRAY_TASK_ID $id is outside the array $min-$((min + shards - 1))"
  fi
  if [ -n "${CELL_SHARDS:-}" ]; then
    declared=$(number CELL_SHARDS "$CELL_SHARDS")
    [ "$declared" = "$shards" ] || die "CELL_SHARDS is $CELL_SHARDS but the SLURM array has $shards tasks"
  fi
  from="SLURM array task $id of $min-$((min + shards - 1))"
elif [ -n "$k8s" ]; then
  completion=$(number JOB_COMPLETION_INDEX "$JOB_COMPLETION_INDEX")
  [ -n "${CELL_SHARDS:-}" ] ||
    die "JOB_COMPLETION_INDEX is set but CELL_SHARDS is not: the Indexed Job must set CELL_SHARDS to its completions"
  shards=$(number CELL_SHARDS "$CELL_SHARDS")
  [ "$shards" -ge 1 ] || die "CELL_SHARDS must be at least 1"
  [ "$completion" -lt "$shards" ] ||
    die "JOB_COMPLETION_INDEX $completion is not below CELL_SHARDS $shards: CELL_SHARDS must equal the Job's completions"
  index=$((completion + 1))
  from="Kubernetes completion index $completion of 0-$((shards - 1))"
else
  die "no scheduler task index: expected SLURM_ARRAY_TASK_ID (a SLURM job array) or JOB_COMPLETION_INDEX with CELL_SHARDS (a Kubernetes Indexed Job)"
fi

cell=${CELL_BIN:-cell}
echo "run-shard.sh: $from: shard $index/$shards" >&2
exec "$cell" run "$scenario" --shard "$index/$shards" --out "$out" "$@"
