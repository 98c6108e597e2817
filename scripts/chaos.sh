#!/usr/bin/env bash
# Chaos run (`make chaos`; figures in docs/RELIABILITY.md): a multi-process deployment on loopback
# (instascene-store, instascene-scheduler over SQLite, two decomposition workers and one training
# worker, one token file) takes a stream of tiny scenes for DURATION seconds (default 180) while a
# random one of its processes is SIGKILLed every KILL_EVERY seconds (default 5) and restarted on the
# same address. Afterwards: every acknowledged job ends succeeded exactly once (one output, one
# key), nothing acknowledged is lost, and the store verifies clean (every blob hashes to its name).
# Exits 1 on a violation. Usage: scripts/chaos.sh [BUILD_DIR]
set -uo pipefail
BUILD=${1:-build}
BIN=$BUILD/clients/cli/instascene
BINDIR=$BUILD/bin
DURATION=${DURATION:-180}
KILL_EVERY=${KILL_EVERY:-5}
SEED=${SEED:-1}
source "$(dirname "$0")/../tests/test_lib.sh"
RANDOM=$SEED

"$BIN" token create --tokens "$WORK/tokens.json" --role worker --out "$WORK/worker.token" >/dev/null || exit 1
"$BIN" token create --tokens "$WORK/tokens.json" --role admin --out "$WORK/admin.token" >/dev/null || exit 1
export INSTASCENE_TOKEN_FILE="$WORK/admin.token"
AUTH="--auth-tokens $WORK/tokens.json --token-file $WORK/worker.token"
declare -A CMD PID
# launch NAME: (re)starts a process from its recorded command line and waits until it serves.
launch() {
  local name=$1
  rm -f "$WORK/ready-$name"
  eval "exec ${CMD[$name]} --ready-file '$WORK/ready-$name'" >>"$WORK/$name.log" 2>&1 8>&- 9>&- &
  PID[$name]=$!
  PIDS+=("$!")
  for _ in $(seq 600); do [ -s "$WORK/ready-$name" ] && return 0; sleep 0.05; done
  echo "FAIL: $name did not come back"; tail -n 5 "$WORK/$name.log"; return 1
}
CMD[store]="'$BINDIR/instascene-store' --data '$WORK/store' --listen 127.0.0.1:0 $AUTH"
launch store || exit 1
STORE=$(head -n 1 "$WORK/ready-store")
CMD[store]="'$BINDIR/instascene-store' --data '$WORK/store' --listen $STORE $AUTH"  # same address on restart
CMD[scheduler]="'$BINDIR/instascene-scheduler' --data '$WORK/sched' --listen 127.0.0.1:0 --store $STORE --lease-seconds 2 $AUTH"
launch scheduler || exit 1
SCHED=$(head -n 1 "$WORK/ready-scheduler")
CMD[scheduler]="'$BINDIR/instascene-scheduler' --data '$WORK/sched' --listen $SCHED --store $STORE --lease-seconds 2 $AUTH"
for w in dec1 dec2; do
  CMD[$w]="'$BINDIR/instascene-decomposition' --data '$WORK/$w' --listen 127.0.0.1:0 --store $STORE --scheduler $SCHED --lease-seconds 2 --threads 1 $AUTH"
done
CMD[train]="'$BINDIR/instascene-training' --data '$WORK/train' --listen 127.0.0.1:0 --store $STORE --scheduler $SCHED --lease-seconds 2 --threads 1 $AUTH"
for w in dec1 dec2 train; do launch "$w" || exit 1; done

# The stream of scenes: one submission every ~2 s; only acknowledged ones are owed a result.
PARAMS='{"train":{"iterations":150,"samples":256,"pixel_pool":512}}'
(
  n=0
  while [ -d "$WORK" ] && [ ! -e "$WORK/stop" ]; do
    n=$((n + 1))
    "$BIN" synth --out "$WORK/s$n" --preset tiny --seed "$n" >/dev/null 2>&1
    if "$BIN" submit --scene "$WORK/s$n" --server "$SCHED" --store "$STORE" --params "$PARAMS" \
         --stages decompose,train,segment --json 2>>"$WORK/submit-errors.txt" | tail -n 1 >"$WORK/sub-$n.json" &&
       [ -s "$WORK/sub-$n.json" ]; then echo "s$n" >>"$WORK/acked.txt"; else rm -f "$WORK/sub-$n.json"; echo "s$n" >>"$WORK/refused.txt"; fi
    sleep 2
  done
) 8>&- 9>&- &
SUBMITTER=$!
PIDS+=("$SUBMITTER")

# The killer.
names=(store scheduler dec1 dec2 train)
kills=0
end=$((SECONDS + DURATION))
while [ $SECONDS -lt $end ]; do
  sleep "$KILL_EVERY"
  if [ "$kills" -lt ${#names[@]} ]; then victim=${names[$kills]}  # each process at least once
  else victim=${names[$((RANDOM % ${#names[@]}))]}; fi
  kill -9 "${PID[$victim]}" 2>/dev/null; wait "${PID[$victim]}" 2>/dev/null
  kills=$((kills + 1))
  echo "$(date +%T) killed $victim" >>"$WORK/kills.txt"
  launch "$victim" || exit 1
done
touch "$WORK/stop"; wait "$SUBMITTER"
acked=$(cat "$WORK/acked.txt" 2>/dev/null | wc -l); refused=$(cat "$WORK/refused.txt" 2>/dev/null | wc -l)
echo "$DURATION s, $kills kills ($(cut -d' ' -f3 "$WORK/kills.txt" | sort | uniq -c | tr -s ' ' | tr '\n' ',')), $acked scenes acknowledged, $refused refused while a process was down"
for s in $(cat "$WORK/acked.txt"); do "$BIN" watch --scene "$s" --server "$SCHED" >/dev/null 2>&1 || echo "scene $s did not finish cleanly"; done
"$BIN" jobs --server "$SCHED" --limit 1000 --json 2>/dev/null | tail -n 1 >"$WORK/all.json"
python3 - "$WORK" <<'PY'
import glob, json, sys, collections
work = sys.argv[1]
jobs = {j["id"]: j for j in json.load(open(work + "/all.json"))["jobs"]}
owed = set()
for f in glob.glob(work + "/sub-*.json"):
    owed.update(j["id"] for j in json.load(open(f))["jobs"])
states = collections.Counter(jobs[i]["state"] for i in owed if i in jobs)
lost = [i for i in owed if i not in jobs]
unfinished = [i for i in owed if i in jobs and jobs[i]["state"] != "succeeded"]
no_output = [i for i in owed if i in jobs and jobs[i]["state"] == "succeeded" and not jobs[i].get("output_manifest")]
retried = sum(jobs[i]["attempts"] > 1 for i in owed if i in jobs)
print(f"acknowledged jobs: {len(owed)}  states: {dict(states)}  retried: {retried}  lost: {len(lost)}  not succeeded: {len(unfinished)}  without output: {len(no_output)}")
for i in unfinished[:5]: print("  ", i, jobs[i]["state"], jobs[i].get("error", "")[:200])
sys.exit(0 if not lost and not unfinished and not no_output else 1)
PY
ok=$?
# The store verifies clean: every blob's bytes hash to its name.
bad=0; blobs=0
while read -r sum path; do
  blobs=$((blobs + 1)); [ "$sum" = "$(basename "$path")" ] || { bad=$((bad + 1)); echo "corrupt blob $path"; }
done < <(find "$WORK/store/store/cas" -type f -print0 | xargs -0 -r sha256sum)
parts=$(find "$WORK/store/store/uploads" -name '*.part' | wc -l)
echo "store: $blobs blobs, $bad corrupt, $parts interrupted uploads left to resume or expire"
[ "$ok" -eq 0 ] && [ "$bad" -eq 0 ]
