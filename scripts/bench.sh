#!/usr/bin/env bash
# `make bench`: Google Benchmark micro-benchmarks and the end-to-end `instascene bench` runs.
# Figures go to stdout; docs/PERFORMANCE.md records them with these exact commands.
set -euo pipefail
BUILD_DIR=${1:-build}
for b in "$BUILD_DIR"/common/*/*_benchmark "$BUILD_DIR"/services/*/*_benchmark; do
  [ -x "$b" ] || continue
  echo "== $b"
  "$b" --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
done
echo "== instascene bench raster (1M Gaussians, 1280x720)"
"$BUILD_DIR/clients/cli/instascene" bench raster --json
