#!/usr/bin/env bash
# Run the sharded bake of deploy/kubernetes/bake-job.yaml: setup, plan, shards, merge,
# each step waited for (kubectl wait --for=condition=complete) before the next.
#
#   deploy/kubernetes/run.sh [--shards N] [--namespace NS] [--timeout SECONDS] [--print]
#
# --shards N   rewrite the three "# ORTM_SHARDS" values of the YAML (default: as written, 4)
# --print      print the YAML that would be applied and exit (needs no cluster)
# Environment: KUBECTL (default kubectl), ORTM_K8S_YAML (default bake-job.yaml beside this file).
#
# Jobs of an earlier run (same names) are deleted first; the volume and the bake
# directory on it are kept, so a rerun resumes or re-merges.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
yaml=${ORTM_K8S_YAML:-$here/bake-job.yaml}
kubectl=${KUBECTL:-kubectl}
shards='' ns=() timeout=86400 print=0
die() { printf 'run.sh: %s\n' "$*" >&2; exit 1; }
while (($#)); do
    case $1 in
        --shards) shards=${2:?}; shift 2 ;;
        --namespace | -n) ns=(--namespace "${2:?}"); shift 2 ;;
        --timeout) timeout=${2:?}; shift 2 ;;
        --print) print=1; shift ;;
        -h | --help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
        *) die "unknown argument '$1' (see --help)" ;;
    esac
done
[[ -z $shards || $shards =~ ^[1-9][0-9]*$ ]] || die "--shards needs a positive integer"

render() {
    if [[ -n $shards ]]; then
        sed -E -e "s/^( *(completions|parallelism): )[0-9]+( .*# ORTM_SHARDS)/\1$shards\3/" \
            -e "s/^( *ORTM_SHARDS: )\"[0-9]+\"( .*# ORTM_SHARDS)/\1\"$shards\"\2/" "$yaml"
    else
        cat "$yaml"
    fi
}
if ((print)); then render; exit 0; fi
command -v "$kubectl" >/dev/null 2>&1 || die "$kubectl not found"

k() { "$kubectl" "${ns[@]}" "$@"; }
# Wait until job $1 is Complete; stop with its pods' logs when it is Failed.
wait_job() {
    local job=$1 start=$SECONDS failed
    printf 'run.sh: waiting for job/%s\n' "$job"
    while :; do
        if k wait --for=condition=complete --timeout=20s "job/$job" >/dev/null 2>&1; then
            printf 'run.sh: job/%s complete after %d s\n' "$job" $((SECONDS - start))
            return 0
        fi
        failed=$(k get "job/$job" -o jsonpath='{.status.conditions[?(@.type=="Failed")].status}')
        if [[ $failed == True ]]; then
            k describe "job/$job" | tail -n 20 >&2 || true
            k logs --tail=30 --prefix -l "job-name=$job" >&2 || true
            die "job/$job failed"
        fi
        ((SECONDS - start < timeout)) || die "job/$job not complete after $timeout s"
    done
}

k delete job -l app.kubernetes.io/name=ortm-bake --ignore-not-found --wait=true
start=$SECONDS
render | k apply -f - -l ortm.bake/step=setup
for step in plan shards merge; do
    render | k apply -f - -l "ortm.bake/step=$step"
    case $step in plan) wait_job ortm-plan ;; shards) wait_job ortm-shards ;; merge) wait_job ortm-merge ;; esac
done
printf 'run.sh: bake done in %d s; the maps are in the volume ortm-bake at ORTM_DIR (see the ConfigMap)\n' $((SECONDS - start))
