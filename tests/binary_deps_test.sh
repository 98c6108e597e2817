#!/usr/bin/env bash
# The scheduler validates stage parameters through the stages' codecs only: its binary must not
# link the stage libraries' heavy dependencies (Embree, OpenCV, OpenImageIO). Checked with ldd.
# Usage: binary_deps_test.sh BIN_DIR
set -euo pipefail
bin="$1/instascene-scheduler"
[ -x "$bin" ] || { echo "FAIL: $bin not built"; exit 1; }
libs=$(ldd "$bin")
bad=$(echo "$libs" | grep -Ei 'embree|opencv|OpenImageIO' || true)
if [ -n "$bad" ]; then
  echo "FAIL: instascene-scheduler links heavy stage dependencies:"
  echo "$bad"
  exit 1
fi
# The worker binaries do link them (sanity check that the test can see a positive).
worker_libs=$(ldd "$1/instascene-decomposition")
echo "$worker_libs" | grep -Eqi 'embree|opencv|OpenImageIO' ||
  { echo "FAIL: expected instascene-decomposition to link the stage libraries' dependencies"; exit 1; }
echo "1 passed, 0 failed"
