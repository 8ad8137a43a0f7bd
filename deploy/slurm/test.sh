#!/usr/bin/env bash
# End-to-end test of the Slurm scripts on a throw-away single-node Slurm cluster.
#
#   bash deploy/slurm/test.sh [path/to/ortm]      (default: target/release/ortm)
#
# Starts munged, slurmctld and slurmd on this machine (no systemd, everything
# under a temporary directory, on ports ORTM_TEST_PORT and ORTM_TEST_PORT+1,
# default 16817), submits through deploy/slurm/submit.sh a sharded bake of
# `maze --size 256` (plan -> 4-task array -> merge), waits for it, bakes the
# same scene in one process and checks that every file of that reference bake
# is byte-identical in the merged directory. Prints the wall time of each phase,
# stops the daemons and removes the temporary directory on exit
# (ORTM_TEST_KEEP=1 keeps it). Exits non-zero on any failure.
#
# Needs root (slurmd runs jobs as the submitting user; SlurmUser=root here) and
# the Debian packages slurm-wlm and munge; it installs nothing itself.
#
# Environment: ORTM_TEST_SHARDS (4), ORTM_TEST_SCENE (maze), ORTM_TEST_SIZE (256),
# ORTM_TEST_SHARD_CPUS (1), ORTM_TEST_TIMEOUT seconds (900), ORTM_TEST_PORT (16817);
# ORTM_TEST_REQUEUE (1): requeue shard 0 while it runs (scontrol requeue, as Slurm
# does on a node failure): it must rerun with the same index, keep its finished
# chunks, and the result must still be byte-identical; 0 skips this.
set -euo pipefail

t_begin=$(date +%s.%N)
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
here=$repo/deploy/slurm
ortm=${1:-$repo/target/release/ortm}
case $ortm in /*) ;; */*) ortm=$PWD/$ortm ;; *) ortm=$(command -v "$ortm" || true) ;; esac
shards=${ORTM_TEST_SHARDS:-4}
scene=${ORTM_TEST_SCENE:-maze}
size=${ORTM_TEST_SIZE:-256}
shard_cpus=${ORTM_TEST_SHARD_CPUS:-1}
timeout=${ORTM_TEST_TIMEOUT:-900}
port=${ORTM_TEST_PORT:-16817}
bake_args=(--size "$size")

say() { printf 'test.sh: %s\n' "$*"; }
fail() { printf 'test.sh: FAIL: %s\n' "$*" >&2; exit 1; }
now() { date +%s.%N; }
secs() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", b - a }'; }

# --- prerequisites ----------------------------------------------------------
missing=()
for tool in munged munge unmunge slurmctld slurmd sbatch scontrol sinfo scancel; do
    command -v "$tool" >/dev/null 2>&1 || missing+=("$tool")
done
if ((${#missing[@]})); then
    printf 'test.sh: missing %s\n' "${missing[*]}" >&2
    printf 'test.sh: install them first, e.g. (Debian/Ubuntu): apt-get install -y slurm-wlm munge\n' >&2
    exit 2
fi
((EUID == 0)) || fail "run as root (slurmd must start jobs; SlurmUser=root in the test cluster)"
[[ -n $ortm && -x $ortm ]] || fail "ortm binary '${1:-$repo/target/release/ortm}' not found (cargo build --release)"
help=$("$ortm" bake --help 2>&1) || fail "$ortm bake --help failed"
if ! grep -q -- '--shard' <<<"$help" || ! grep -q -- '--merge' <<<"$help"; then
    fail "$ortm bake has no --shard/--merge (sharded bake not built in this binary)"
fi

# --- throw-away cluster -----------------------------------------------------
tmp=$(mktemp -d /tmp/ortm-slurm-test.XXXXXX)
chmod 700 "$tmp"
pids=()
jobs_submitted=()
cleanup() {
    local rc=$?
    set +e
    if ((${#jobs_submitted[@]})); then scancel "${jobs_submitted[@]}" 2>/dev/null; fi
    if [[ -n ${SLURM_CONF:-} ]]; then scontrol shutdown >/dev/null 2>&1; fi
    local pid
    for pid in "${pids[@]}"; do
        for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
        kill "$pid" 2>/dev/null
    done
    for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null; done
    if ((rc != 0)) && [[ -d $tmp/log ]]; then
        say "daemon logs (tails):"
        tail -n 15 "$tmp"/log/*.log 2>/dev/null
    fi
    if [[ ${ORTM_TEST_KEEP:-0} == 1 ]]; then say "kept $tmp"; else rm -rf "$tmp"; fi
    exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

if command -v ss >/dev/null 2>&1 && ss -ltn | awk '{ print $4 }' | grep -Eq ":($port|$((port + 1)))\$"; then
    fail "port $port or $((port + 1)) is in use (another Slurm?): set ORTM_TEST_PORT"
fi
mkdir -p "$tmp"/{munge,state,spool,log,run}
node=$(hostname -s)
cpus=$(nproc)

t0=$(now)
dd if=/dev/urandom of="$tmp/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$tmp/munge/munge.key"
socket=$tmp/munge/munge.socket
munged -F --force --key-file="$tmp/munge/munge.key" --socket="$socket" \
    --pid-file="$tmp/run/munged.pid" --log-file="$tmp/log/munged.log" \
    --seed-file="$tmp/munge/munge.seed" 2>>"$tmp/log/munged.log" &
pids+=($!)
for _ in $(seq 50); do [[ -S $socket ]] && break; sleep 0.1; done
munge -S "$socket" -n | unmunge -S "$socket" >/dev/null || fail "munged does not work (see $tmp/log/munged.log)"

cat >"$tmp/slurm.conf" <<CONF
ClusterName=ortmtest
SlurmctldHost=$node(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$socket
CredType=cred/munge
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool/slurmd-%n
SlurmctldPidFile=$tmp/run/slurmctld.pid
SlurmdPidFile=$tmp/run/slurmd.pid
SlurmctldLogFile=$tmp/log/slurmctld.log
SlurmdLogFile=$tmp/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SwitchType=switch/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MinJobAge=3600
SlurmctldTimeout=30
SlurmdTimeout=60
NodeName=$node NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=test Nodes=$node Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$tmp/slurm.conf

slurmctld -D -c -f "$SLURM_CONF" >>"$tmp/log/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D -f "$SLURM_CONF" -N "$node" >>"$tmp/log/slurmd.out" 2>&1 &
pids+=($!)
state=
for _ in $(seq 300); do
    state=$(sinfo -h -n "$node" -o %T 2>/dev/null || true)
    [[ $state == idle ]] && break
    for pid in "${pids[@]}"; do kill -0 "$pid" 2>/dev/null || fail "a daemon exited at start-up"; done
    sleep 0.2
done
[[ $state == idle ]] || fail "node $node did not become idle (state '${state:-none}')"
t_cluster=$(now)
say "slurm up: node $node, $cpus CPUs, in $(secs "$t0" "$t_cluster") s ($tmp)"

# --- sharded bake through submit.sh -----------------------------------------
bake=$tmp/bake
logs=$tmp/jobs
t_submit=$(now)
ids=$(ORTM="$ortm" ORTM_LOG_DIR="$logs" ORTM_PLAN_CPUS="$cpus" ORTM_MERGE_CPUS="$cpus" \
    ORTM_SHARD_CPUS="$shard_cpus" bash "$here/submit.sh" "$scene" "$bake" "$shards" "${bake_args[@]}") ||
    fail "submit.sh failed"
printf '%s\n' "$ids"
plan_id=$(awk '$1 == "plan" { print $2 }' <<<"$ids")
array_id=$(awk '$1 == "shards" { print $2 }' <<<"$ids")
merge_id=$(awk '$1 == "merge" { print $2 }' <<<"$ids")
[[ -n $plan_id && -n $array_id && -n $merge_id ]] || fail "submit.sh printed no job ids"
jobs_submitted=("$plan_id" "$array_id" "$merge_id")

# States of all jobs (array tasks one line each), from slurmctld.
job_states() {
    local id
    for id in "$@"; do
        scontrol show job -o "$id" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | cut -d= -f2
    done
}
terminal='^(COMPLETED|FAILED|CANCELLED|TIMEOUT|NODE_FAIL|OUT_OF_MEMORY|BOOT_FAIL|DEADLINE|PREEMPTED)$'
deadline=$(($(date +%s) + timeout))

# Optional: requeue shard 0 while it runs, as Slurm does when its node fails; it
# must resume from its finished chunks and the merged bake must not change.
requeued=0
if [[ ${ORTM_TEST_REQUEUE:-1} == 1 ]]; then
    task0=${array_id}_0
    chunks0=$bake/shard_0_of_$shards
    while :; do
        st=$(job_states "$task0")
        if [[ $st == RUNNING ]] && compgen -G "$chunks0/chunk_*.bin" >/dev/null; then break; fi
        if [[ $st =~ $terminal ]]; then
            say "shard 0 ended ($st) before it wrote a chunk that could be seen: requeue test skipped"
            break
        fi
        (($(date +%s) < deadline)) || fail "timed out waiting for shard 0 to write a chunk"
        sleep 0.1
    done
    if [[ $st == RUNNING ]]; then
        kept=$(find "$chunks0" -name 'chunk_*.bin' | wc -l)
        scontrol requeue "$task0" || fail "scontrol requeue $task0 failed"
        say "requeued shard 0 ($task0) while running, with $kept chunk(s) written"
        # A requeued job waits ~2 min (BeginTime) before it may start again; skip that.
        for _ in $(seq 100); do
            [[ $(job_states "$task0") == PENDING ]] && scontrol update JobId="$task0" StartTime=now 2>/dev/null && break
            sleep 0.1
        done
        requeued=1
    fi
fi
while :; do
    merge_state=$(job_states "$merge_id")
    [[ $merge_state =~ $terminal ]] && break
    (($(date +%s) < deadline)) || fail "timed out after $timeout s (merge job $merge_id: $merge_state)"
    sleep 0.5
done
t_done=$(now)

show_logs() {
    local f
    for f in "$logs"/*.out; do
        [[ -e $f ]] || continue
        printf -- '--- %s\n' "${f##*/}"
        tail -n 20 "$f"
    done
}
if [[ $merge_state != COMPLETED ]]; then
    say "job states: plan $(job_states "$plan_id" | xargs), shards $(job_states "$array_id" | xargs), merge $merge_state"
    show_logs
    fail "sharded bake did not complete"
fi

# Phase times from the stamps bake.sbatch writes ("ortm-slurm: MODE start|end rc=R EPOCH").
stamps() { # MODE start|end FILES... -> epochs, one a line
    local mode=$1 what=$2
    shift 2
    awk -v m="$mode" -v w="$what" '$1 == "ortm-slurm:" && $2 == m && $3 == w { print $NF }' "$@"
}
plan_s=$(stamps plan start "$logs"/plan-*.out | sort -n | head -1)
plan_e=$(stamps plan end "$logs"/plan-*.out | sort -n | tail -1)
shard_s=$(stamps shard start "$logs"/shard-*.out | sort -n | head -1)
shard_e=$(stamps shard end "$logs"/shard-*.out | sort -n | tail -1)
merge_s=$(stamps merge start "$logs"/merge-*.out | sort -n | head -1)
merge_e=$(stamps merge end "$logs"/merge-*.out | sort -n | tail -1)
[[ -n $plan_s && -n $plan_e && -n $shard_s && -n $shard_e && -n $merge_s && -n $merge_e ]] ||
    { show_logs; fail "job logs lack start/end stamps"; }
n_logs=$(find "$logs" -name 'shard-*.out' | wc -l)
((n_logs == shards)) || fail "expected $shards shard logs, found $n_logs"
if ((requeued)); then
    log0=$logs/shard-${array_id}_0.out
    runs=$(stamps shard start "$log0" | wc -l)
    ((runs >= 2)) || { show_logs; fail "shard 0 was requeued but ran $runs time(s)"; }
    say "shard 0 ran $runs times (requeued), its last run:"
    awk '$1 == "ortm-slurm:" && $2 == "job" { n++ } n >= 2' "$log0" | tail -n 12
fi

# --- single-process reference and byte identity ------------------------------
ref=$tmp/ref
t_ref=$(now)
"$ortm" bake "$scene" -o "$ref" "${bake_args[@]}" >"$tmp/log/ref.out" 2>&1 ||
    { tail -n 20 "$tmp/log/ref.out"; fail "single-process reference bake failed"; }
t_ref_end=$(now)

n_files=0
bad=0
while IFS= read -r -d '' f; do
    rel=${f#"$ref"/}
    n_files=$((n_files + 1))
    if [[ ! -f $bake/$rel ]]; then
        say "missing in the merged bake: $rel"
        bad=$((bad + 1))
    elif ! cmp -s "$f" "$bake/$rel"; then
        say "differs: $rel"
        bad=$((bad + 1))
    fi
done < <(find "$ref" -type f -print0)
((n_files > 0)) || fail "the reference bake wrote no files"
extra=$(cd "$bake" && find . -type f | sed 's|^\./||' | while IFS= read -r rel; do
    [[ -e $ref/$rel ]] || printf '%s\n' "$rel"
done)
leftover=$(grep -E '^(transport\.bin|shard_)' <<<"$extra" || true)
if [[ -n $extra ]]; then say "files only in the merged bake: $(xargs <<<"$extra")"; fi
[[ -z $leftover ]] || { say "merge left: $(xargs <<<"$leftover")"; bad=$((bad + 1)); }
((bad == 0)) || fail "$bad of $n_files reference files differ or are missing in the merged bake"
maps=("$ref"/map_*)
say "byte-identical: all $n_files files of the single-process bake (${#maps[@]} maps)"
t_end=$(now)

printf 'test.sh: PASS  %s --size %s, %s shards x %s CPU, %s CPUs on %s\n' \
    "$scene" "$size" "$shards" "$shard_cpus" "$cpus" "$node"
row() { printf '  %-28s %7s %s%s\n' "$1" "$2" "${2:+s}" "${3:-}"; }
row "slurm start-up" "$(secs "$t0" "$t_cluster")"
row "plan (job $plan_id)" "$(secs "$plan_s" "$plan_e")"
row "shards (array $array_id)" "$(secs "$shard_s" "$shard_e")" "  first start to last end"
per_shard=$(for f in "$logs"/shard-*.out; do
    awk '$1 == "ortm-slurm:" && $2 == "shard" && $3 == "start" { s = $NF }
         $1 == "ortm-slurm:" && $2 == "shard" && $3 == "end" { printf "%.1f ", $NF - s }' "$f"
done)
printf "  %-28s %s s\n" "  each shard" "${per_shard% }"
row "merge (job $merge_id)" "$(secs "$merge_s" "$merge_e")"
row "submit -> merge done" "$(secs "$t_submit" "$t_done")" "  with scheduling gaps"
row "single-process bake" "$(secs "$t_ref" "$t_ref_end")"
row "compare" "$(secs "$t_ref_end" "$t_end")"
row "test total" "$(secs "$t_begin" "$t_end")" "  before shutdown"
