#!/bin/sh
# Runs one fuzz target of ortm (see docs/fuzzing.md) for SECONDS (default 600) on one core:
#   fuzz/run.sh TARGET [SECONDS]
# The corpus grows in fuzz/corpus/TARGET (seeded from fuzz/seeds/TARGET); crashing, leaking,
# slow or out-of-memory inputs land in fuzz/artifacts/TARGET. Fork mode keeps going after a
# crash, so one run reports every kind of failure it finds.
set -eu
cd "$(dirname "$0")"
t=$1
secs=${2:-600}
mkdir -p "corpus/$t" "artifacts/$t"
exec cargo +nightly fuzz run -O "$t" "corpus/$t" "seeds/$t" -- \
  -max_total_time="$secs" -fork=1 -ignore_crashes=1 -ignore_ooms=1 -ignore_timeouts=1 \
  -rss_limit_mb=2048 -malloc_limit_mb=2048 -timeout=10 -max_len=65536 \
  -artifact_prefix="artifacts/$t/" -print_final_stats=1
