#!/usr/bin/env bash
# `make bench-web`: the web UI's figures in docs/PERFORMANCE.md, in Debian's Chromium on loopback:
# time to the first drawn frame of the viewer for a 100k-Gaussian scene (median of 5 cold loads)
# and the Server-Sent Events latency from a job update to the page. Usage: bench_web.sh [BUILD_DIR]
set -euo pipefail
BUILD_DIR=$(cd "${1:-build}" && pwd)
BIN="$BUILD_DIR/clients/cli/instascene"
WORK=$(mktemp -d)
trap 'kill $SERVER 2>/dev/null || true; wait 2>/dev/null || true; rm -rf "$WORK"' EXIT
"$BIN" synth --out "$WORK/big" --preset small --gaussians 100000 --views 24 --seed 4 >/dev/null 2>&1
"$BIN" synth --out "$WORK/live" --preset small --seed 5 >/dev/null 2>&1
"$BIN" serve --data "$WORK/data" --listen 127.0.0.1:0 --gateway 127.0.0.1:0 --ready-file "$WORK/ready" \
  >"$WORK/serve.log" 2>&1 &
SERVER=$!
for _ in $(seq 200); do [ -s "$WORK/ready" ] && break; sleep 0.05; done
ADDR=$(head -n 1 "$WORK/ready")
GW=http://$(sed -n 's/^gateway=//p' "$WORK/ready")
export INSTASCENE_TOKEN_FILE="$WORK/data/auth/admin.token"
"$BIN" submit --scene "$WORK/big" --server "$ADDR" --stages decompose,train,segment >/dev/null
"$BIN" watch --scene big --server "$ADDR" >/dev/null
"$BIN" submit --scene "$WORK/live" --server "$ADDR" --stages decompose,train,segment >/dev/null
HOME="$WORK" node "$BUILD_DIR/web-build/tests/bench_viewer.mjs" "$GW" "$(cat "$INSTASCENE_TOKEN_FILE")" big 5 live
