#!/usr/bin/env bash
# `make memcheck` (figures in docs/RELIABILITY.md): the whole offline pipeline (`instascene run`:
# decompose, train, segment, complete, export) and the evaluation of its result on a tiny synthetic
# scene under Valgrind's memcheck, one thread. It reports what the sanitizers of `make
# test-sanitize` cannot: reads of uninitialised memory (an Eigen vector is not zeroed by its
# default constructor; result.json's centroids once came out of such reads). Exits 1 on any error
# Valgrind reports. About 10 minutes on 2 cores.
# Usage: [ITERATIONS=N] [SEED=N] scripts/memcheck.sh [BUILD_DIR]
set -uo pipefail
BUILD=${1:-build}
BIN=$BUILD/clients/cli/instascene
ITERATIONS=${ITERATIONS:-30}
SEED=${SEED:-5}
command -v valgrind >/dev/null || { echo "memcheck: valgrind is missing (scripts/install-deps.sh)"; exit 1; }
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
"$BIN" synth --out "$WORK/scene" --preset tiny --seed "$SEED" >/dev/null 2>&1 || exit 1
status=0
memcheck() {  # memcheck NAME ARGS...: one command under memcheck; prints its error summary
  local name=$1
  shift
  local start=$SECONDS
  valgrind --error-exitcode=9 --track-origins=yes --num-callers=30 --log-file="$WORK/$name.log" \
    "$BIN" "$@" >/dev/null 2>&1
  local rc=$?
  printf "%-6s %5d s  %s\n" "$name" $((SECONDS - start)) "$(grep -h 'ERROR SUMMARY' "$WORK/$name.log" | sed 's/^==[0-9]*== //')"
  if [ $rc -ne 0 ]; then
    status=1
    echo "memcheck: $name exited $rc; the first report:"
    grep -m1 -A30 -E "uninitialised|Invalid|definitely lost|Mismatched" "$WORK/$name.log" | sed 's/^==[0-9]*== //'
  fi
}
memcheck run run --scene "$WORK/scene" --out "$WORK/run" --iterations "$ITERATIONS" --threads 1
memcheck eval eval --scene "$WORK/scene" --result "$WORK/run/segmentation" --threads 1
exit $status
