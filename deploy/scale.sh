#!/usr/bin/env bash
# Scaling of a sharded bake on this machine (README, "Sharded bake"): the single-process bake,
# then for N = 1, 2, 4: the plan, each shard one after another (each with the whole machine, as
# on N machines), the merge — wall seconds of each — and whether the merged directory is
# byte-identical to the single-process one.
#
#   bash deploy/scale.sh "maze --size 512 --tolerance 1e-3" /tmp/scale [path/to/ortm]
#
# Run it on a quiet machine: other work changes the times by a third or more.
set -euo pipefail
args=$1
work=$2
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
ortm=${3:-$repo/target/release/ortm}
case $ortm in /*) ;; *) ortm=$PWD/$ortm ;; esac
[[ -x $ortm ]] || { echo "scale.sh: no ortm binary at $ortm (cargo build --release)" >&2; exit 2; }
mkdir -p "$work"
cd "$work"
# Wall seconds of one command (its output goes to <name>.log).
timed() {
    local log=$1; shift
    local s e
    s=$(date +%s.%N)
    "$@" >"$log.log" 2>&1 || { echo "scale.sh: '$*' failed, see $work/$log.log" >&2; exit 1; }
    e=$(date +%s.%N)
    awk -v a="$s" -v b="$e" 'BEGIN { printf "%.1f", b - a }'
}
read -r -a a <<<"$args"
rm -rf single
echo "single process: $(timed single "$ortm" bake "${a[@]}" -o single) s"
for n in 1 2 4; do
    rm -rf "s$n"
    plan=$(timed "plan$n" "$ortm" bake "${a[@]}" -o "s$n" --plan --shards "$n")
    shards=""
    for ((i = 0; i < n; i++)); do
        shards+=" $(timed "shard${i}_$n" "$ortm" bake "${a[@]}" -o "s$n" --shard "$i/$n")"
    done
    merge=$(timed "merge$n" "$ortm" bake "s$n" --merge)
    same=yes
    for f in single/*; do cmp -s "$f" "s$n/${f#single/}" || same=no; done
    echo "N=$n: plan $plan s, shards$shards s, merge $merge s, byte-identical: $same"
done
