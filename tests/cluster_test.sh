#!/usr/bin/env bash
# A scale-out cluster on loopback: a real PostgreSQL and an S3-compatible server (moto, SigV4
# checked) started here; the store service on S3 (for the CLI's uploads and downloads), two
# scheduler replicas sharing the PostgreSQL queue, and three workers as separate processes with
# separate scratch folders (decomposition and training on replica A, a second training worker on
# replica B); schedulers and workers reach the blobs in S3 directly. Ten scenes are submitted;
# replica B and its worker are SIGKILLed while that worker runs a job. Every job must end succeeded
# exactly once: no job lost, none recorded twice, every result in the store (S3, nothing on local
# disk). Then `instascene gc` collects the S3 store from the PostgreSQL queue with the services
# running. Prints "N passed, N failed"; exits 1 on any failure.
set -uo pipefail
BIN=$1      # the instascene command
BINDIR=$2   # folder with instascene-store, -scheduler, -decomposition, -training
source "$(dirname "$0")/test_lib.sh"
source "$(dirname "$0")/cluster_lib.sh"
start_postgres
start_s3 instascene-cluster
# One token file for the cluster: processes reach each other with a worker token, the CLI is admin.
check "a worker token" "$BIN" token create --tokens "$WORK/tokens.json" --role worker --out "$WORK/worker.token"
check "an admin token" "$BIN" token create --tokens "$WORK/tokens.json" --role admin --out "$WORK/admin.token"
export INSTASCENE_TOKEN_FILE="$WORK/admin.token"
AUTH="--auth-tokens $WORK/tokens.json --token-file $WORK/worker.token"

start store "$WORK/ready-store" "$BINDIR/instascene-store" --data "$WORK/store" --store "$STORE_URI" --listen 127.0.0.1:0 --ready-file "$WORK/ready-store" $AUTH
STORE=$(cat "$WORK/ready-store")
for r in a b; do
  start "sched-$r" "$WORK/ready-$r" "$BINDIR/instascene-scheduler" --data "$WORK/sched-$r" --queue "$QUEUE" \
    --store "$STORE_URI" --listen 127.0.0.1:0 --ready-file "$WORK/ready-$r" $AUTH --lease-seconds 2
done
A=$(cat "$WORK/ready-a")
B=$(cat "$WORK/ready-b")
SCHED_B=$LAST_PID  # the last started: replica b
start dec "$WORK/ready-dec" "$BINDIR/instascene-decomposition" --data "$WORK/w-dec" --store "$STORE_URI" --scheduler "$A" --lease-seconds 2 --ready-file "$WORK/ready-dec" $AUTH
start train-a "$WORK/ready-ta" "$BINDIR/instascene-training" --data "$WORK/w-ta" --store "$STORE_URI" --scheduler "$A" --lease-seconds 2 --ready-file "$WORK/ready-ta" $AUTH
start train-b "$WORK/ready-tb" "$BINDIR/instascene-training" --data "$WORK/w-tb" --store "$STORE_URI" --scheduler "$B" --lease-seconds 2 --ready-file "$WORK/ready-tb" $AUTH
TRAIN_B=$LAST_PID

# As soon as replica B's worker starts a training job (its log says so: an event, not a poll of the
# queue), ask replica B for the queue, then kill the replica and the worker while the job runs.
(
  busy=$(grep -m1 -o "job j[0-9a-f]* (train of" < <(exec timeout 300 tail -n +1 -f "$WORK/train-b.log" 2>/dev/null) | cut -d' ' -f2)
  "$BIN" jobs --server "$B" --json --limit 100 2>/dev/null | tail -n 1 >"$WORK/b-jobs.json"
  kill -9 "$SCHED_B" "$TRAIN_B" 2>/dev/null
  pkill -f -- "tail -n +1 -f $WORK/train-b.log"
  echo "$busy" >"$WORK/busy"
) 8>&- 9>&- &
KILLER=$!

PARAMS='{"train":{"iterations":600,"samples":256,"pixel_pool":512}}'
for s in $(seq 10); do
  check "synth scene $s" "$BIN" synth --out "$WORK/s$s" --preset tiny --seed "$s"
  check "submit scene $s through replica A" "$BIN" submit --scene "$WORK/s$s" --server "$A" --store "$STORE" --params "$PARAMS" --stages decompose,train,segment --json
done
wait "$KILLER"
busy=$(cat "$WORK/busy")
check "replica B's worker took a job" test -n "$busy"
# Held: leased, or running once its first heartbeat arrived (the log line comes at the lease).
check "replica B saw the shared queue, its job held" test \
  "$(json_get "$WORK/b-jobs.json" "len(d['jobs']) >= 3 and [j['state'] for j in d['jobs'] if j['id'] == '$busy'] in (['leased'], ['running'])")" = "True"
for s in $(seq 10); do check "scene $s finishes on replica A" "$BIN" watch --scene "s$s" --server "$A"; done
"$BIN" jobs --server "$A" --json --limit 100 2>/dev/null | tail -n 1 > "$WORK/final.json"
check "thirty jobs, all succeeded" test "$(json_get "$WORK/final.json" "sorted(set(j['state'] for j in d['jobs'])) == ['succeeded'] and len(d['jobs'])")" = "30"
check "the killed worker's job ran again (2 attempts), every other once" test \
  "$(json_get "$WORK/final.json" "sorted((j['id'] == '$busy', j['attempts']) for j in d['jobs'])[-1]")" = "(True, 2)"
check "no other job ran twice" test "$(json_get "$WORK/final.json" "sum(j['attempts'] for j in d['jobs'])")" = "31"
check "every result is in the store" "$BIN" fetch --scene s1 --out "$WORK/f1" --server "$A" --store "$STORE"
for s in $(seq 2 10); do check "fetch scene $s" "$BIN" fetch --scene "s$s" --out "$WORK/f$s" --server "$A" --store "$STORE"; done

check "the blobs are in S3" test "$(s3_count cas/)" -gt 30
check "no upload left staged in S3" test "$(s3_count uploads/)" = 0
check "nothing was stored on local disk" test ! -e "$WORK/store/store"

# Garbage collection of the scale-out storage with the services running (no grace period: every
# unreachable blob is old enough): an orphan blob granted to a tenant goes with its grant, what
# the thirty jobs reach stays, and every scene still fetches.
orphan=$(python3 -c "
import boto3, hashlib
s3 = boto3.client('s3', endpoint_url='$S3_ENDPOINT', region_name='us-east-1')
body = b'an upload never submitted'
h = hashlib.sha256(body).hexdigest()
s3.put_object(Bucket='$S3_BUCKET', Key='cluster/cas/' + h, Body=body)
s3.put_object(Bucket='$S3_BUCKET', Key='cluster/grants/acme/%s-%d' % (h, len(body)), Body=b'')
print(h)")
check "an orphan blob and its grant in S3" test "$(s3_count "cas/$orphan")$(s3_count "grants/acme/$orphan")" = 11
check "gc, dry run, services running" "$BIN" gc --store "$STORE_URI" --queue "$QUEUE" --grace-hours 0 --dry-run --json
would=$(json_get "$WORK/out.txt" "(d['removed_blobs'], d['removed_grants'])")
check "gc read the thirty jobs as roots" test "$(json_get "$WORK/out.txt" "d['jobs'] == 30 and d['live_blobs'] > 30 and d['missing_manifests'] == 0 and d['removed_blobs'] >= 1 and d['removed_grants'] >= 1")" = True
check "gc, services running" "$BIN" gc --store "$STORE_URI" --queue "$QUEUE" --grace-hours 0 --json
check "gc removed what the dry run counted" test "$(json_get "$WORK/out.txt" "(d['removed_blobs'], d['removed_grants'])")" = "$would"
check "the orphan and its grant are gone" test "$(s3_count "cas/$orphan")$(s3_count "grants/acme/$orphan")" = 00
for s in $(seq 10); do check "scene $s fetches after gc" "$BIN" fetch --scene "s$s" --out "$WORK/g$s" --server "$A" --store "$STORE"; done
check "gc again: nothing left to remove" "$BIN" gc --store "$STORE_URI" --queue "$QUEUE" --grace-hours 0 --json
check "nothing removed the second time" test "$(json_get "$WORK/out.txt" "d['removed_blobs'] + d['removed_grants']")" = 0
check_fails "gc wants --store and --queue together" "go together" "$BIN" gc --store "$STORE_URI"
check_fails "gc refuses a store service's address" "not a store service" "$BIN" gc --store "$STORE" --queue "$QUEUE"
check_fails "gc refuses a queue URI it does not know" "expected sqlite:PATH or postgres://" "$BIN" gc --store "$STORE_URI" --queue mysql://db/jobs

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
