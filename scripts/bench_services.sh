#!/usr/bin/env bash
# Service-level figures (docs/PERFORMANCE.md, "Services"): upload of a medium-preset scene through
# the store (first and second time), and the small-preset pipeline through `instascene serve` vs the
# same stages offline (`instascene run`). Usage: scripts/bench_services.sh [BUILD_DIR]
set -euo pipefail
BUILD_DIR=${1:-build}
BIN="$BUILD_DIR/clients/cli/instascene"
WORK=$(mktemp -d)
trap 'kill -TERM $(jobs -p) 2>/dev/null || true; rm -rf "$WORK"' EXIT
SERVER_PID=
ADDR=
now() { date +%s.%N; }
serve() {  # serve DATA WORKERS: starts a server, sets ADDR and SERVER_PID
  rm -f "$WORK/ready"
  "$BIN" serve --data "$1" --listen 127.0.0.1:0 --ready-file "$WORK/ready" --workers "$2" >"$WORK/serve.log" 2>&1 &
  SERVER_PID=$!
  for _ in $(seq 200); do [ -s "$WORK/ready" ] && break; sleep 0.05; done
  ADDR=$(cat "$WORK/ready")
  export INSTASCENE_TOKEN_FILE="$1/auth/admin.token"  # written on first start
}

"$BIN" synth --out "$WORK/medium" --preset medium --seed 1 >/dev/null 2>&1
"$BIN" synth --out "$WORK/small" --preset small --seed 7 >/dev/null 2>&1

serve "$WORK/data-upload" none
t0=$(now); "$BIN" submit --scene "$WORK/medium" --server "$ADDR" --json 2>/dev/null | tail -n 1 > "$WORK/up1.json"; t1=$(now)
"$BIN" submit --scene "$WORK/medium" --server "$ADDR" --json 2>/dev/null | tail -n 1 > "$WORK/up2.json"; t2=$(now)
kill -TERM "$SERVER_PID"; wait "$SERVER_PID" || true
python3 - "$WORK" "$t0" "$t1" "$t2" <<'PY'
import json, sys
w, t0, t1, t2 = sys.argv[1], *map(float, sys.argv[2:])
a, b = json.load(open(w + "/up1.json")), json.load(open(w + "/up2.json"))
print(f"upload medium scene: {a['uploaded_files']} files, {a['uploaded_bytes']/1e6:.1f} MB in {t1-t0:.2f} s "
      f"({a['uploaded_bytes']/1e6/(t1-t0):.0f} MB/s incl. hashing and submit); "
      f"again: {b['uploaded_files']} files, {b['uploaded_bytes']} bytes in {t2-t1:.2f} s")
PY

t0=$(now); "$BIN" run --scene "$WORK/small" --out "$WORK/offline" >/dev/null 2>&1; t1=$(now)
serve "$WORK/data-run" all
t2=$(now); "$BIN" submit --scene "$WORK/small" --server "$ADDR" --wait >/dev/null 2>&1; t3=$(now)
kill -TERM "$SERVER_PID"; wait "$SERVER_PID" || true
python3 -c "print(f'small preset pipeline: offline run {$t1-$t0:.1f} s, through instascene serve {$t3-$t2:.1f} s (upload + queue + fetch inputs + upload outputs)')"
