#!/usr/bin/env bash
# A scale-out cluster on loopback: a real PostgreSQL started here, the store service, two scheduler
# replicas sharing the PostgreSQL queue, and three workers as separate processes with separate
# scratch folders (decomposition and training on replica A, a second training worker on replica B).
# Four scenes are submitted; replica B and its worker are SIGKILLed while that worker runs a job.
# Every job must end succeeded exactly once: no job lost, none recorded twice, every result in the
# store. Prints "N passed, N failed"; exits 1 on any failure.
set -uo pipefail
BIN=$1      # the instascene command
BINDIR=$2   # folder with instascene-store, -scheduler, -decomposition, -training
source "$(dirname "$0")/test_lib.sh"
chmod 755 "$WORK"  # the PostgreSQL server runs as the postgres user

PGBIN=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -n 1)
[ -x "$PGBIN/initdb" ] || { echo "FAIL: no PostgreSQL server (scripts/install-deps.sh installs postgresql-15)"; exit 1; }
AS=""
if [ "$(id -u)" = 0 ]; then AS="runuser -u postgres --"; fi
mkdir -p "$WORK/pg" && { [ -z "$AS" ] || chown postgres: "$WORK/pg"; }
$AS "$PGBIN/initdb" -D "$WORK/pg/data" -U postgres --auth=trust --no-sync >"$WORK/initdb.log" 2>&1 ||
  { echo "FAIL: initdb"; cat "$WORK/initdb.log"; exit 1; }
$AS "$PGBIN/pg_ctl" -D "$WORK/pg/data" -l "$WORK/pg/server.log" -w -t 60 \
  -o "-c listen_addresses='' -c unix_socket_directories='$WORK/pg' -c fsync=off -p 5433" start >/dev/null ||
  { echo "FAIL: pg_ctl start"; cat "$WORK/pg/server.log"; exit 1; }
stop_postgres() { $AS "$PGBIN/pg_ctl" -D "$WORK/pg/data" -m immediate -w stop >/dev/null 2>&1; }
trap 'stop_postgres; cleanup' EXIT
QUEUE="postgresql:///postgres?host=$WORK/pg&port=5433&user=postgres"

start store "$WORK/ready-store" "$BINDIR/instascene-store" --data "$WORK/store" --listen 127.0.0.1:0 --ready-file "$WORK/ready-store"
STORE=$(cat "$WORK/ready-store")
for r in a b; do
  start "sched-$r" "$WORK/ready-$r" "$BINDIR/instascene-scheduler" --data "$WORK/sched-$r" --queue "$QUEUE" \
    --store "$STORE" --listen 127.0.0.1:0 --ready-file "$WORK/ready-$r" --lease-seconds 2
done
A=$(cat "$WORK/ready-a")
B=$(cat "$WORK/ready-b")
SCHED_B=${PIDS[2]}
start dec "$WORK/ready-dec" "$BINDIR/instascene-decomposition" --data "$WORK/w-dec" --store "$STORE" --scheduler "$A" --lease-seconds 2 --ready-file "$WORK/ready-dec"
start train-a "$WORK/ready-ta" "$BINDIR/instascene-training" --data "$WORK/w-ta" --store "$STORE" --scheduler "$A" --lease-seconds 2 --ready-file "$WORK/ready-ta"
start train-b "$WORK/ready-tb" "$BINDIR/instascene-training" --data "$WORK/w-tb" --store "$STORE" --scheduler "$B" --lease-seconds 2 --ready-file "$WORK/ready-tb"
TRAIN_B=$LAST_PID

PARAMS='{"train":{"iterations":1500,"samples":256,"pixel_pool":512}}'
for s in 1 2 3 4; do
  check "synth scene $s" "$BIN" synth --out "$WORK/s$s" --preset tiny --seed "$s"
  check "submit scene $s through replica A" "$BIN" submit --scene "$WORK/s$s" --server "$A" --store "$STORE" --params "$PARAMS" --stages decompose,train,segment --json
done
check "replica B sees the same queue" test "$(json_get <("$BIN" jobs --server "$B" --json) "len(d['jobs'])")" = "12"
# Wait until replica B's worker runs a training job, then kill the replica and the worker.
busy=""
for _ in $(seq 600); do
  busy=$("$BIN" jobs --server "$A" --json --limit 100 2>/dev/null | tail -n 1 | python3 -c "
import json, sys
d = json.load(sys.stdin)
print(next((j['id'] for j in d['jobs'] if j['state'] == 'running' and j['worker'].endswith('-$TRAIN_B-train+segment')), ''))")
  [ -n "$busy" ] && break
  sleep 0.1
done
check "replica B's worker took a job" test -n "$busy"
kill -9 "$SCHED_B" "$TRAIN_B" 2>/dev/null
for s in 1 2 3 4; do check "scene $s finishes on replica A" "$BIN" watch --scene "s$s" --server "$A"; done
"$BIN" jobs --server "$A" --json --limit 100 2>/dev/null | tail -n 1 > "$WORK/final.json"
check "twelve jobs, all succeeded" test "$(json_get "$WORK/final.json" "sorted(set(j['state'] for j in d['jobs'])) == ['succeeded'] and len(d['jobs'])")" = "12"
check "the killed worker's job ran again (2 attempts), every other once" test \
  "$(json_get "$WORK/final.json" "sorted((j['id'] == '$busy', j['attempts']) for j in d['jobs'])[-1]")" = "(True, 2)"
check "no other job ran twice" test "$(json_get "$WORK/final.json" "sum(j['attempts'] for j in d['jobs'])")" = "13"
check "every result is in the store" "$BIN" fetch --scene s1 --out "$WORK/f1" --server "$A" --store "$STORE"
for s in 2 3 4; do check "fetch scene $s" "$BIN" fetch --scene "s$s" --out "$WORK/f$s" --server "$A" --store "$STORE"; done

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
