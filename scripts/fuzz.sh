#!/usr/bin/env bash
# `make fuzz`: builds the libFuzzer harnesses (tests/fuzz/) with clang, ASan and UBSan in
# build-fuzz/ and runs each for FUZZ_SECONDS (default 60; with FUZZ_RUNS=N, until N executions or
# FUZZ_SECONDS, whichever comes first) on a copy of its seed corpus
# (tests/fuzz/corpus/<harness>/). Prints executions, coverage and the outcome per harness; a crash
# leaves its input under build-fuzz/crashes/<harness>/ (turn it into a regression test) and makes
# the script exit 1. docs/RELIABILITY.md records a run.
# Usage: [FUZZ_SECONDS=N] [FUZZ_RUNS=N] [FUZZ_DIR=DIR] scripts/fuzz.sh [HARNESS...]
set -uo pipefail
DIR=${FUZZ_DIR:-build-fuzz}
EACH=${FUZZ_SECONDS:-60}
RUNS=()
[ -z "${FUZZ_RUNS:-}" ] || RUNS=(-runs="$FUZZ_RUNS")
HARNESSES=("$@")
[ ${#HARNESSES[@]} -gt 0 ] || HARNESSES=(ply scene_json manifest stage_params transforms_json colmap image_probe)
cmake -S . -B "$DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ \
  -DINSTASCENE_FUZZ=ON -DINSTASCENE_WERROR=OFF -DINSTASCENE_BUILD_BENCHMARKS=OFF >/dev/null || exit 1
cmake --build "$DIR" --target fuzzers || exit 1
status=0
corpus=""
trap '[ -z "$corpus" ] || rm -rf "$corpus"' EXIT
printf "%-16s %12s %10s %8s  %s\n" harness executions exec/s cov outcome
for h in "${HARNESSES[@]}"; do
  corpus=$(mktemp -d)
  cp "tests/fuzz/corpus/$h/"* "$corpus/"
  mkdir -p "$DIR/crashes/$h"
  log="$DIR/fuzz-$h.log"
  if UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
      LSAN_OPTIONS=suppressions=tests/fuzz/lsan.supp "$DIR/tests/fuzz/${h}_fuzz" \
      -max_total_time="$EACH" "${RUNS[@]}" -print_final_stats=1 -rss_limit_mb=2048 -max_len=65536 \
      -artifact_prefix="$DIR/crashes/$h/" "$corpus" >"$log" 2>&1; then
    outcome="0 crashes"
  else
    outcome="CRASH (see $log and $DIR/crashes/$h/)"
    status=1
  fi
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo "?")
  rate=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo "?")
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -n 1 | grep -o '[0-9]*$' || echo "?")
  printf "%-16s %12s %10s %8s  %s\n" "$h" "$runs" "$rate" "$cov" "$outcome"
  rm -rf "$corpus"
done
exit $status
