#!/usr/bin/env bash
# Submits a sharded `cell run` to SLURM: a job array of SHARDS tasks (cell-run.sbatch, one shard
# each) and the merge (cell-merge.sbatch), which waits for every task to succeed
# (--dependency=afterok). Prints both job ids.
#
# Usage: deploy/slurm/submit.sh SCENARIO OUT SHARDS [cell run options...]
#   OUT must be on a file system every node shares. CELL_IMAGE (an Apptainer image of
#   deploy/Containerfile) or CELL_BIN (default: `cell` on PATH) say which cell runs.
#   Example: deploy/slurm/submit.sh scenarios/usbc_nominal.toml /shared/runs 16 --episodes 2000
#   With an image: CELL_IMAGE=/shared/cell.sif deploy/slurm/submit.sh \
#     /opt/cell/scenarios/usbc_nominal.toml /shared/runs 16 --episodes 2000
set -euo pipefail
[ $# -ge 3 ] || {
  echo "usage: deploy/slurm/submit.sh SCENARIO OUT SHARDS [cell run options...]" >&2
  exit 2
}
[[ $3 =~ ^[1-9][0-9]*$ ]] || {
  echo "submit.sh: SHARDS is '$3', not a positive whole number" >&2
  exit 2
}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
CELL_SCENARIO=$1
# A host file by its absolute path (the tasks run elsewhere); else a path inside CELL_IMAGE.
[ ! -f "$CELL_SCENARIO" ] || CELL_SCENARIO=$(realpath "$CELL_SCENARIO")
CELL_OUT=$(realpath -m "$2")
shards=$3
shift 3
CELL_RUN_ARGS="$*"
CELL_DEPLOY_DIR=$(dirname "$here")
export CELL_SCENARIO CELL_OUT CELL_RUN_ARGS CELL_DEPLOY_DIR
mkdir -p "$CELL_OUT"
run=$(sbatch --parsable --array="1-$shards" "$here/cell-run.sbatch")
run=${run%%;*} # --parsable prints JOBID[;CLUSTER]
merge=$(sbatch --parsable --dependency="afterok:$run" --kill-on-invalid-dep=yes "$here/cell-merge.sbatch")
merge=${merge%%;*}
echo "shards: job array $run (1-$shards); merge: job $merge, after every shard succeeded"
echo "results: $CELL_OUT/<scenario>/shard-I-of-$shards, merged into $CELL_OUT/<scenario>/merged"
