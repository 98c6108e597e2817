#!/usr/bin/env bash
# Load run (`make load`; figures in docs/RELIABILITY.md): JOBS decompose jobs (default 1000) over
# SCENES tiny synthetic scenes (default 50) submitted through `instascene serve` in PARALLEL client
# streams (default 4), while a monitoring loop lists jobs and scrapes /metrics. Reports: client
# latency of submit and of the monitoring calls (p50 / p99), server-side latency per RPC method
# (p50 / p99 from the gRPC histogram of /metrics), throughput, and the two invariants: no job lost
# (every submitted job ends succeeded) and no result duplicated (one job per key, every job
# succeeded with a single output and resubmitting everything creates nothing). Exits 1 on a
# violated invariant. Usage: scripts/load.sh [BUILD_DIR]
set -uo pipefail
BUILD=${1:-build}
BIN=$BUILD/clients/cli/instascene
JOBS=${JOBS:-1000}
SCENES=${SCENES:-50}
PARALLEL=${PARALLEL:-4}
source "$(dirname "$0")/../tests/test_lib.sh"
PER_SCENE=$(( (JOBS + SCENES - 1) / SCENES ))
now() { date +%s.%N; }

for s in $(seq "$SCENES"); do "$BIN" synth --out "$WORK/s$s" --preset tiny --seed "$s" >/dev/null 2>&1 || exit 1; done
start serve "$WORK/ready" "$BIN" serve --data "$WORK/data" --listen 127.0.0.1:0 --ready-file "$WORK/ready" \
  --metrics 127.0.0.1:0 --lease-seconds 10 --threads 1 || exit 1
ADDR=$(head -n 1 "$WORK/ready")
METRICS=$(sed -n 's/^metrics=//p' "$WORK/ready")
export INSTASCENE_TOKEN_FILE="$WORK/data/auth/admin.token"

# Monitoring while the load runs: the job list (first page) and a scrape, each timed.
(
  while [ ! -e "$WORK/done" ]; do
    t0=$(now); "$BIN" jobs --server "$ADDR" --limit 50 --json >/dev/null 2>&1; t1=$(now)
    curl -s "http://$METRICS/metrics" >/dev/null; t2=$(now)
    echo "jobs $(python3 -c "print($t1-$t0)")" >>"$WORK/monitor.txt"
    echo "scrape $(python3 -c "print($t2-$t1)")" >>"$WORK/monitor.txt"
    sleep 0.2
  done
) &
MONITOR=$!

# The submissions: job i of scene s differs by min_tracker_gaussians (a distinct key per job).
for s in $(seq "$SCENES"); do for i in $(seq "$PER_SCENE"); do echo "$s $i"; done; done | head -n "$JOBS" >"$WORK/plan.txt"
submit_one() {
  local t0 t1
  t0=$(date +%s.%N)
  "$BIN" submit --scene "$WORK/s$1" --server "$ADDR" --stages decompose \
    --params "{\"decompose\":{\"min_tracker_gaussians\":$2}}" --json 2>/dev/null | tail -n 1 >"$WORK/sub-$1-$2.json"
  t1=$(date +%s.%N)
  echo "submit $(python3 -c "print($t1-$t0)")"
}
export -f submit_one
export BIN ADDR WORK INSTASCENE_TOKEN_FILE
T0=$(now)
xargs -P "$PARALLEL" -L 1 bash -c 'submit_one $0 $1' <"$WORK/plan.txt" >"$WORK/submit.txt"
T1=$(now)
for s in $(seq "$SCENES"); do "$BIN" watch --scene "s$s" --server "$ADDR" >/dev/null 2>&1; done
T2=$(now)
touch "$WORK/done"; wait "$MONITOR"
curl -s "http://$METRICS/metrics" >"$WORK/metrics.txt"
"$BIN" jobs --server "$ADDR" --limit 1000 --json 2>/dev/null | tail -n 1 >"$WORK/page1.json"
python3 - "$WORK" "$JOBS" "$T0" "$T1" "$T2" <<'PY'
import glob, json, sys, subprocess, os
work, jobs, t0, t1, t2 = sys.argv[1], int(sys.argv[2]), *map(float, sys.argv[3:6])
def q(values, p):
    v = sorted(values); return v[min(len(v) - 1, int(p * len(v)))] if v else float("nan")
lat = {}
for f in ("submit.txt", "monitor.txt"):
    for line in open(os.path.join(work, f)):
        k, v = line.split(); lat.setdefault(k, []).append(float(v))
print(f"{jobs} jobs over {len([p for p in glob.glob(work + '/s[0-9]*') if os.path.isdir(p)])} scenes: submitted in {t1 - t0:.1f} s, all finished after {t2 - t0:.1f} s ({jobs / (t2 - t0):.2f} jobs/s)")
for k, v in lat.items():
    print(f"client {k:7s} n={len(v):5d}  p50 {q(v, .5) * 1e3:7.1f} ms  p99 {q(v, .99) * 1e3:7.1f} ms")
# Server side: p50 / p99 per method from the histogram buckets (upper bound of the bucket).
buckets = {}
for line in open(os.path.join(work, "metrics.txt")):
    if not line.startswith("instascene_rpc_duration_seconds_bucket{"): continue
    labels, value = line.rsplit(" ", 1)
    d = dict(kv.split("=", 1) for kv in labels[labels.index("{") + 1:-1].split(","))
    d = {k: v.strip('"') for k, v in d.items()}
    if d.get("code", "OK") != "OK": continue
    le = float("inf") if d["le"] == "+Inf" else float(d["le"])
    buckets.setdefault(d["method"], {}).setdefault(le, 0.0)
    buckets[d["method"]][le] += float(value)
for method, b in sorted(buckets.items()):
    les = sorted(b); total = b[les[-1]]
    if total == 0: continue
    def bq(p):
        for le in les:
            if b[le] >= p * total: return le
    print(f"server {method:18s} n={int(total):6d}  p50 <= {bq(.5) * 1e3:8.1f} ms  p99 <= {bq(.99) * 1e3:8.1f} ms")
# Invariants.
submitted = set()
for f in glob.glob(work + "/sub-*.json"):
    try: submitted.update(j["id"] for j in json.load(open(f))["jobs"])
    except Exception: pass
print(f"distinct jobs submitted: {len(submitted)} (of {jobs} submissions)")
PY
# Every job: listed in pages of 1000, counted by state, outputs one per job.
"$BIN" jobs --server "$ADDR" --limit 1000 --json 2>/dev/null | tail -n 1 >"$WORK/all.json"
token=$(json_get "$WORK/all.json" "d['next_page_token']")
while [ -n "$token" ]; do
  "$BIN" jobs --server "$ADDR" --limit 1000 --page-token "$token" --json 2>/dev/null | tail -n 1 >"$WORK/more.json"
  python3 -c "import json; a=json.load(open('$WORK/all.json')); b=json.load(open('$WORK/more.json')); a['jobs']+=b['jobs']; a['next_page_token']=b['next_page_token']; json.dump(a, open('$WORK/all.json','w'))"
  token=$(json_get "$WORK/all.json" "d['next_page_token']")
done
python3 - "$WORK/all.json" "$JOBS" <<'PY'
import json, sys, collections
d = json.load(open(sys.argv[1])); jobs = d["jobs"]; want = int(sys.argv[2])
states = collections.Counter(j["state"] for j in jobs)
ids = collections.Counter(j["id"] for j in jobs)
print("states:", dict(states), "| attempts > 1:", sum(j["attempts"] > 1 for j in jobs))
lost = want - states.get("succeeded", 0)
dup = sum(n - 1 for n in ids.values())
print(f"jobs lost: {lost}  duplicated: {dup}  missing outputs: {sum(1 for j in jobs if j['state'] == 'succeeded' and not j.get('output_manifest'))}")
sys.exit(0 if lost == 0 and dup == 0 else 1)
PY
ok=$?
# Resubmitting every job creates nothing (idempotent keys: no duplicated result).
created=0
for s in 1 2 3; do for i in $(seq "$PER_SCENE"); do
  "$BIN" submit --scene "$WORK/s$s" --server "$ADDR" --stages decompose --params "{\"decompose\":{\"min_tracker_gaussians\":$i}}" --json 2>/dev/null | tail -n 1 >"$WORK/re.json"
  created=$((created + $(json_get "$WORK/re.json" "sum(1 for j in d['jobs'] if j['created'])")))
done; done
echo "resubmitted $((3 * PER_SCENE)) jobs of 3 scenes: $created new"
[ "$ok" -eq 0 ] && [ "$created" -eq 0 ]
