#!/usr/bin/env bash
# Scale-out throughput (docs/PERFORMANCE.md, "Scale-out"): the loopback cluster of the
# scaleout_cluster test (PostgreSQL queue, S3 store via moto, the store service, one scheduler)
# with 1 vs 3 worker sets (a set: one instascene-decomposition + one instascene-training process,
# --threads 1 each), N tiny scenes through decompose,train,segment; REPEATS runs per setting,
# median wall time from the first submit to the last scene done.
# Usage: scripts/bench_cluster.sh [BUILD_DIR] [SCENES=6] [REPEATS=3]
set -uo pipefail
BUILD_DIR=$(cd "${1:-build}" && pwd)
SCENES=${2:-6}
REPEATS=${3:-3}
BIN="$BUILD_DIR/clients/cli/instascene"
BINDIR="$BUILD_DIR/bin"
source "$(dirname "$0")/../tests/test_lib.sh"
source "$(dirname "$0")/../tests/cluster_lib.sh"
start_postgres
start_s3 instascene-bench
now() { date +%s.%N; }
for s in $(seq "$SCENES"); do "$BIN" synth --out "$WORK/s$s" --preset tiny --seed "$s" >/dev/null 2>&1; done
PARAMS='{"train":{"iterations":1500,"samples":256,"pixel_pool":512}}'
# One token file for the processes (worker token between them, admin token for the CLI).
"$BIN" token create --tokens "$WORK/tokens.json" --role worker --out "$WORK/worker.token" >/dev/null
"$BIN" token create --tokens "$WORK/tokens.json" --role admin --out "$WORK/admin.token" >/dev/null
export INSTASCENE_TOKEN_FILE="$WORK/admin.token"
AUTH="--auth-tokens $WORK/tokens.json --token-file $WORK/worker.token"
run=0
for sets in 1 3; do
  for rep in $(seq "$REPEATS"); do
    run=$((run + 1))
    db="bench$run"
    runuser -u postgres -- psql -q -h "$WORK/pg" -p 5433 -U postgres -c "CREATE DATABASE $db" 2>/dev/null ||
      psql -q -h "$WORK/pg" -p 5433 -U postgres -c "CREATE DATABASE $db"
    queue="postgresql:///$db?host=$WORK/pg&port=5433&user=postgres"
    uri="s3://$S3_BUCKET/run$run?endpoint=$S3_ENDPOINT&query_slash=literal"
    first=${#PIDS[@]}
    start "store$run" "$WORK/rs$run" "$BINDIR/instascene-store" --data "$WORK/st$run" --store "$uri" --listen 127.0.0.1:0 --ready-file "$WORK/rs$run" $AUTH
    start "sched$run" "$WORK/rq$run" "$BINDIR/instascene-scheduler" --data "$WORK/sc$run" --queue "$queue" --store "$uri" --listen 127.0.0.1:0 --ready-file "$WORK/rq$run" $AUTH
    store=$(cat "$WORK/rs$run"); sched=$(cat "$WORK/rq$run")
    for w in $(seq "$sets"); do
      start "dec$run-$w" "$WORK/rd$run-$w" "$BINDIR/instascene-decomposition" --data "$WORK/wd$run-$w" --store "$uri" --scheduler "$sched" --threads 1 --ready-file "$WORK/rd$run-$w" $AUTH
      start "tr$run-$w" "$WORK/rt$run-$w" "$BINDIR/instascene-training" --data "$WORK/wt$run-$w" --store "$uri" --scheduler "$sched" --threads 1 --ready-file "$WORK/rt$run-$w" $AUTH
    done
    t0=$(now)
    for s in $(seq "$SCENES"); do
      "$BIN" submit --scene "$WORK/s$s" --server "$sched" --store "$store" --params "$PARAMS" --stages decompose,train,segment --json >/dev/null 2>&1
    done
    for s in $(seq "$SCENES"); do "$BIN" watch --scene "s$s" --server "$sched" >/dev/null 2>&1 || echo "scene $s failed"; done
    t1=$(now)
    echo "$sets $(python3 -c "print($t1 - $t0)")" >>"$WORK/times.txt"
    for p in "${PIDS[@]:$first}"; do kill -TERM "$p" 2>/dev/null; done
    for p in "${PIDS[@]:$first}"; do wait "$p" 2>/dev/null; done
  done
done
python3 - "$WORK/times.txt" "$SCENES" <<'PY'
import statistics, sys
rows = [l.split() for l in open(sys.argv[1])]
n = int(sys.argv[2])
med = {}
for sets in ("1", "3"):
    t = sorted(float(r[1]) for r in rows if r[0] == sets)
    med[sets] = statistics.median(t)
    print(f"{sets} worker set(s): {n} scenes in median {med[sets]:.1f} s "
          f"(runs {', '.join(f'{x:.1f}' for x in t)}) = {60 * n / med[sets]:.1f} scenes/min")
print(f"speed-up 3 vs 1: {med['1'] / med['3']:.2f}x")
PY
