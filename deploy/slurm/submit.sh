#!/usr/bin/env bash
# Submit a sharded `ortm bake` to Slurm: plan -> N-task array -> merge.
#
#   deploy/slurm/submit.sh SCENE DIR N [bake args...]
#
# SCENE  built-in scene name (cornell, maze, head) or scene file
# DIR    bake directory on storage that every node sees (NFS, Lustre, ...)
# N      number of shards (array tasks)
# bake args: ortm bake options (--size 256 --offsets 300 ...), the same for all steps
#
# Prints one line per job on stdout:  plan JOBID / shards JOBID / merge JOBID
#
# Environment (all optional):
#   ORTM               ortm binary as the compute nodes see it (default: ortm on PATH)
#   ORTM_LOG_DIR       Slurm log files (default: DIR.logs, beside DIR)
#   ORTM_SBATCH_ARGS   extra sbatch options for all three jobs, split on white space
#                      (e.g. "--partition=bake --time=02:00:00 --account=lab")
#   ORTM_PLAN_CPUS, ORTM_SHARD_CPUS, ORTM_MERGE_CPUS
#                      --cpus-per-task of each step (default: the cluster's default)
#   ORTM_SHARD_MEM     --mem of each shard (e.g. 16G; default: the cluster's default)
#   ORTM_ARRAY_LIMIT   at most this many shards at once (sbatch --array=...%K)
#   ORTM_SBATCH_SCRIPT the job script (default: bake.sbatch beside this file)
set -euo pipefail

usage() {
    sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//' >&2
    exit 2
}
die() { printf 'submit.sh: %s\n' "$*" >&2; exit 1; }

(($# >= 3)) || usage
scene=$1 dir=$2 n=$3
shift 3
bake_args=("$@")
[[ $n =~ ^[1-9][0-9]*$ ]] || die "N must be a positive integer, got '$n'"

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
script=${ORTM_SBATCH_SCRIPT:-$here/bake.sbatch}
[[ -r $script ]] || die "job script $script not found"
command -v sbatch >/dev/null 2>&1 || die "sbatch not found (is Slurm installed and SLURM_CONF set?)"

# Absolute paths: the jobs may start in another directory.
abspath() { case $1 in /*) printf '%s\n' "$1" ;; *) printf '%s/%s\n' "$PWD" "$1" ;; esac; }
dir=$(abspath "$dir")
dir=${dir%/}
case $scene in
    cornell | maze | head | head-exponential) ;; # built-in names win over files
    *) [[ -e $scene ]] && scene=$(abspath "$scene") ;;
esac
ortm=${ORTM:-ortm}
[[ $ortm == */* ]] && ortm=$(abspath "$ortm")
export ORTM=$ortm
if [[ $ortm == */* ]]; then
    [[ -x $ortm ]] || die "ORTM=$ortm is not an executable file"
else
    command -v "$ortm" >/dev/null 2>&1 || printf 'submit.sh: warning: %s is not on PATH here; the nodes must have it\n' "$ortm" >&2
fi

logs=$(abspath "${ORTM_LOG_DIR:-$dir.logs}")
mkdir -p "$logs" "$(dirname "$dir")"

# shellcheck disable=SC2206  # options only, split on white space on purpose
common=(--parsable --export=ALL --kill-on-invalid-dep=yes ${ORTM_SBATCH_ARGS:-})
cpus() { [[ -n ${1:-} ]] && printf -- '--cpus-per-task=%s\n' "$1"; return 0; }
jobid() { local out; out=$("$@") || die "sbatch failed: $*"; printf '%s\n' "${out%%;*}"; }

mapfile -t plan_opts < <(cpus "${ORTM_PLAN_CPUS:-}")
mapfile -t shard_opts < <(cpus "${ORTM_SHARD_CPUS:-}")
mapfile -t merge_opts < <(cpus "${ORTM_MERGE_CPUS:-}")
[[ -n ${ORTM_SHARD_MEM:-} ]] && shard_opts+=("--mem=$ORTM_SHARD_MEM")
array="0-$((n - 1))"
[[ -n ${ORTM_ARRAY_LIMIT:-} ]] && array+="%$ORTM_ARRAY_LIMIT"

submitted=()
cancel() { ((${#submitted[@]})) && scancel "${submitted[@]}" 2>/dev/null; return 0; }
trap 'cancel' ERR
plan=$(jobid sbatch "${common[@]}" "${plan_opts[@]}" --job-name=ortm-plan \
    --output="$logs/plan-%j.out" \
    "$script" plan "$scene" "$dir" "$n" "${bake_args[@]}")
submitted+=("$plan")
printf 'plan %s\n' "$plan"

shards=$(jobid sbatch "${common[@]}" "${shard_opts[@]}" --job-name=ortm-shard \
    --array="$array" --dependency="afterok:$plan" \
    --output="$logs/shard-%A_%a.out" \
    "$script" shard "$scene" "$dir" "${bake_args[@]}")
submitted+=("$shards")
printf 'shards %s\n' "$shards"

merge=$(jobid sbatch "${common[@]}" "${merge_opts[@]}" --job-name=ortm-merge \
    --dependency="afterok:$shards" \
    --output="$logs/merge-%j.out" \
    "$script" merge "$dir")
printf 'merge %s\n' "$merge"

printf 'submit.sh: %s shards of %s into %s; logs in %s\n' "$n" "$scene" "$dir" "$logs" >&2
