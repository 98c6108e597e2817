#!/usr/bin/env bash
# Monitoring (issue 16): promtool checks the scrape configuration and the alert rules and runs the
# alerts' unit tests (deploy/monitoring/); a pipeline through `instascene serve --metrics` shows
# up in /metrics (jobs by stage and state, queue waits, leases, finished jobs, worker durations,
# RPC latencies, store and disk, the Objects service's index cache), and `promtool check metrics` passes on the output of serve and
# of every per-service binary; the Grafana dashboard's every query evaluates on a real Prometheus
# scraping them. Prints "N passed, N failed"; exits 1 on any failure.
set -uo pipefail
BIN=$1      # the instascene command
BINDIR=$2   # folder with instascene-store, -scheduler, -decomposition, -training, -generation, -objects
SRC=$3      # the source tree (deploy/monitoring)
source "$(dirname "$0")/test_lib.sh"
command -v promtool >/dev/null || { echo "FAIL: promtool missing (scripts/install-deps.sh installs prometheus)"; exit 1; }
MON="$SRC/deploy/monitoring"

check "promtool check config" promtool check config "$MON/prometheus.yml"
check "promtool check rules" promtool check rules "$MON/alerts.yml"
check "promtool test rules (the alerts fire as specified)" bash -c "cd '$MON' && promtool test rules alerts_test.yml"

scrape() {  # scrape HOST:PORT FILE
  python3 -c "import sys, urllib.request; sys.stdout.write(urllib.request.urlopen('http://$1/metrics', timeout=10).read().decode())" >"$2"
}
metric() {  # metric FILE PATTERN: the value of the first sample line matching PATTERN (regex)
  python3 - "$1" "$2" <<'PY'
import re, sys
for line in open(sys.argv[1]):
    if not line.startswith('#') and re.search(sys.argv[2], line):
        print(float(line.rsplit(' ', 1)[1])); break
else:
    print('absent')
PY
}
positive() { python3 -c "import sys; sys.exit(0 if '$1' != 'absent' and float('$1') > 0 else 1)"; }

# 1. The embedded server: a pipeline, then its metrics.
check "synth scene" "$BIN" synth --out "$WORK/s" --preset tiny --seed 6
start serve "$WORK/ready" "$BIN" serve --data "$WORK/data" --listen 127.0.0.1:0 --ready-file "$WORK/ready" --metrics 127.0.0.1:0
ADDR=$(head -n 1 "$WORK/ready")
METRICS=$(sed -n 's/^metrics=//p' "$WORK/ready")
export INSTASCENE_TOKEN_FILE="$WORK/data/auth/admin.token"  # written by serve on first start
check "the ready file names the metrics address" test -n "$METRICS"
check "submit" "$BIN" submit --scene "$WORK/s" --server "$ADDR" --stages decompose,train,segment \
  --params '{"train":{"iterations":40,"samples":512,"pixel_pool":1024}}' --json
IDS=$(json_get "$WORK/out.txt" "' '.join(j['id'] for j in d['jobs'])")
check "watch until done" "$BIN" watch $IDS --server "$ADDR" --json
check "an object, twice (one index load, one cache hit)" bash -c \
  "'$BIN' object --scene s --id 1 --server '$ADDR' >/dev/null && '$BIN' object --scene s --id 1 --server '$ADDR' >/dev/null"
check "scrape serve" scrape "$METRICS" "$WORK/serve.txt"
check "promtool check metrics (serve)" bash -c "promtool check metrics < '$WORK/serve.txt'"
check "segment succeeded in instascene_jobs" test "$(metric "$WORK/serve.txt" '^instascene_jobs\{stage="segment",state="succeeded"\}')" = 1.0
check "three jobs finished as succeeded" test "$(python3 -c "
import re
print(sum(float(l.rsplit(' ',1)[1]) for l in open('$WORK/serve.txt') if l.startswith('instascene_jobs_finished_total{') and 'outcome=\"succeeded\"' in l))")" = 3.0
check "a queue wait per lease" test "$(metric "$WORK/serve.txt" '^instascene_job_queue_wait_seconds_count\{stage="train"\}')" = 1.0
check "leases counted" test "$(metric "$WORK/serve.txt" '^instascene_job_leases_total\{stage="decompose"\}')" = 1.0
check "worker durations by stage and outcome" test "$(metric "$WORK/serve.txt" '^instascene_worker_job_duration_seconds_count\{.*stage="train"')" = 1.0
check "no job running now" test "$(metric "$WORK/serve.txt" '^instascene_worker_jobs_running\{stage="segment"\}')" = 0.0
check "LeaseJob latencies by code" positive "$(metric "$WORK/serve.txt" '^instascene_rpc_duration_seconds_count\{.*method="LeaseJob"')"
check "store bytes" positive "$(metric "$WORK/serve.txt" '^instascene_store_bytes ')"
check "store blobs" positive "$(metric "$WORK/serve.txt" '^instascene_store_blobs ')"
check "disk capacity" positive "$(metric "$WORK/serve.txt" '^instascene_data_dir_capacity_bytes ')"
check "one objects index loaded" test "$(metric "$WORK/serve.txt" '^instascene_objects_index_loads_total\{outcome="ok"\}')" = 1.0
check "and no load failed" test "$(metric "$WORK/serve.txt" '^instascene_objects_index_loads_total\{outcome="failed"\}')" = 0.0
check "one objects cache hit" test "$(metric "$WORK/serve.txt" '^instascene_objects_index_hits_total ')" = 1.0
check "the load's duration" test "$(metric "$WORK/serve.txt" '^instascene_objects_index_load_seconds_count ')" = 1.0
check "the objects cache's bytes" positive "$(metric "$WORK/serve.txt" '^instascene_objects_index_cache_bytes ')"
check "no queued job left (no age series)" test "$(metric "$WORK/serve.txt" '^instascene_queue_oldest_queued_age_seconds')" = absent
check_fails "a taken metrics port is refused" "cannot listen on $METRICS" \
  "$BIN" serve --data "$WORK/data2" --listen 127.0.0.1:0 --metrics "$METRICS"

# 2. Every per-service binary serves metrics that promtool accepts (one token file for all, each
# process reaching the others with a worker token).
check "a worker token" "$BIN" token create --tokens "$WORK/tokens.json" --role worker --out "$WORK/worker.token"
AUTH="--auth-tokens $WORK/tokens.json --token-file $WORK/worker.token"
start store "$WORK/r-store" "$BINDIR/instascene-store" --data "$WORK/d-store" --listen 127.0.0.1:0 --ready-file "$WORK/r-store" --metrics 127.0.0.1:0 $AUTH
STORE=$(head -n 1 "$WORK/r-store")
start scheduler "$WORK/r-sched" "$BINDIR/instascene-scheduler" --data "$WORK/d-sched" --listen 127.0.0.1:0 --ready-file "$WORK/r-sched" --store "$STORE" --metrics 127.0.0.1:0 $AUTH
SCHED=$(head -n 1 "$WORK/r-sched")
for svc in decomposition training generation objects; do
  start "$svc" "$WORK/r-$svc" "$BINDIR/instascene-$svc" --data "$WORK/d-$svc" --listen 127.0.0.1:0 --store "$STORE" --scheduler "$SCHED" --ready-file "$WORK/r-$svc" --metrics 127.0.0.1:0 $AUTH
done
for svc in store sched decomposition training generation objects; do
  M=$(sed -n 's/^metrics=//p' "$WORK/r-$svc")
  check "scrape instascene-$svc" scrape "$M" "$WORK/m-$svc.txt"
  check "promtool check metrics (instascene-$svc)" bash -c "promtool check metrics < '$WORK/m-$svc.txt'"
done
# The gateway: HTTP requests by route and code.
start gateway "$WORK/r-gateway" "$BINDIR/instascene-gateway" --listen 127.0.0.1:0 --scheduler "$SCHED" --store "$STORE" \
  --objects "$(head -n 1 "$WORK/r-objects")" --ready-file "$WORK/r-gateway" --metrics 127.0.0.1:0
GW=$(head -n 1 "$WORK/r-gateway")
check "gateway health" curl -sf "http://$GW/api/v1/health"
check "gateway health again" curl -sf "http://$GW/api/v1/health"
curl -s "http://$GW/api/v1/jobs" >/dev/null
check "scrape instascene-gateway" scrape "$(sed -n 's/^metrics=//p' "$WORK/r-gateway")" "$WORK/m-gateway.txt"
check "promtool check metrics (instascene-gateway)" bash -c "promtool check metrics < '$WORK/m-gateway.txt'"
check "HTTP requests by route and code" test "$(metric "$WORK/m-gateway.txt" '^instascene_http_requests_total\{code="200",route="health"\}')" = 2.0
check "refusals counted with their code" test "$(metric "$WORK/m-gateway.txt" '^instascene_http_requests_total\{code="401",route="jobs"\}')" = 1.0
check "request durations" positive "$(metric "$WORK/m-gateway.txt" '^instascene_http_request_duration_seconds_count\{route="health"\}')"
check "the scheduler reports the queue" grep -q '^# TYPE instascene_jobs gauge' "$WORK/m-sched.txt"
check "the store reports its blobs" grep -q '^instascene_store_blobs ' "$WORK/m-store.txt"
check "instascene-objects reports its index cache" grep -q '^instascene_objects_index_cache_entries 0' "$WORK/m-objects.txt"
check "a worker reports no store of its own" test "$(metric "$WORK/m-training.txt" '^instascene_store_blobs ')" = absent

# 3. The Grafana dashboard against a real Prometheus scraping all of the above every second: every
# panel's query evaluates and (but for a documented few) returns data (tests/monitoring/).
targets="\"$METRICS\""
for svc in store sched decomposition training generation objects gateway; do
  targets="$targets, \"$(sed -n 's/^metrics=//p' "$WORK/r-$svc")\""
done
printf 'global:\n  scrape_interval: 1s\nscrape_configs:\n  - job_name: instascene\n    static_configs:\n      - targets: [%s]\n' \
  "$targets" >"$WORK/prometheus.yml"
check "promtool check config (the test's Prometheus)" promtool check config "$WORK/prometheus.yml"
prometheus --config.file="$WORK/prometheus.yml" --storage.tsdb.path="$WORK/tsdb" \
  --web.listen-address=127.0.0.1:0 >"$WORK/prometheus.log" 2>&1 8>&- 9>&- &
PIDS+=("$!")
PROM=""
for _ in $(seq 300); do  # its log names the bound port (30 s at most)
  PROM=$(sed -n 's/.*msg="Listening on" address=\([0-9.:]*\).*/\1/p' "$WORK/prometheus.log")
  [ -n "$PROM" ] && break
  sleep 0.1
done
check "Prometheus started" test -n "$PROM"
check "the dashboard's every query on real data (deploy/monitoring/grafana)" \
  python3 "$(dirname "$0")/monitoring/dashboard_check.py" "$MON/grafana/instascene.json" "http://$PROM" 8 \
  "$WORK/serve.txt" "$WORK"/m-*.txt
tail -n 1 "$WORK/out.txt"

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
