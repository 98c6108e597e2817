#!/usr/bin/env bash
# Integration test of the service backbone over loopback: `instascene serve` (store + scheduler +
# workers), the per-service binaries, and the client commands. Covers: the whole pipeline through
# the services gives the same labels as `instascene run`; resubmission computes nothing; a worker
# killed with SIGKILL mid-job (lease expires, retry succeeds, one result); the server killed with
# SIGKILL and restarted (every job survives); cancellation; SIGTERM drain handing a job back; bad
# requests rejected with the right status; per-object completion jobs on the generation worker
# (a degenerate object fails only its own job). Prints "N passed, N failed"; exits 1 on any failure.
set -uo pipefail
BIN=$1      # the instascene command
BINDIR=$2   # folder with instascene-store, -scheduler, -decomposition, -training, -generation
source "$(dirname "$0")/test_lib.sh"

SMALL='{"train":{"iterations":60,"samples":512,"pixel_pool":1024}}'
PIPE="--stages decompose,train,segment"  # sections 1-7; section 8 adds per-object completion
slow() { echo "{\"train\":{\"iterations\":$1,\"samples\":512,\"pixel_pool\":1024}}"; }  # ~1.5 ms/step
check "synth scene A" "$BIN" synth --out "$WORK/a" --preset tiny --seed 3
check "synth scene B" "$BIN" synth --out "$WORK/b" --preset tiny --seed 4

# 1. The whole pipeline through the embedded server equals the offline run.
start serve "$WORK/ready" "$BIN" serve --data "$WORK/data" --listen 127.0.0.1:0 --ready-file "$WORK/ready" --lease-seconds 2
SERVE=$LAST_PID
ADDR=$(cat "$WORK/ready")
# The admin token serve wrote on first start (the CLI finds it by itself in ./instascene-data).
export INSTASCENE_TOKEN_FILE="$WORK/data/auth/admin.token"
check "serve wrote an admin token on first start" test -s "$INSTASCENE_TOKEN_FILE"
check "readable by its owner only" test "$(stat -c %a "$INSTASCENE_TOKEN_FILE")" = "600"
check_fails "a second serve on the same data folder is refused" "in use by another process" \
  "$BIN" serve --data "$WORK/data" --listen 127.0.0.1:0
check_fails "a second serve on the same port is refused" "cannot listen on $ADDR" \
  "$BIN" serve --data "$WORK/data-other" --listen "$ADDR"
check "submit scene A" "$BIN" submit --scene "$WORK/a" --server "$ADDR" --params "$SMALL" $PIPE --json
cp "$WORK/out.txt" "$WORK/submit1.json"
check "submit json has scene and 3 jobs" test "$(json_get "$WORK/submit1.json" "d['scene'] + str(len(d['jobs']))")" = "a3"
SEG=$(json_get "$WORK/submit1.json" "d['jobs'][2]['id']")
TRAIN=$(json_get "$WORK/submit1.json" "d['jobs'][1]['id']")
DEC=$(json_get "$WORK/submit1.json" "d['jobs'][0]['id']")
check "watch until done" "$BIN" watch "$SEG" "$TRAIN" "$DEC" --server "$ADDR" --json
check "fetch segment result" "$BIN" fetch "$SEG" --out "$WORK/fetched" --server "$ADDR" --json
check "fetched instances" test -s "$WORK/fetched/instances.json"
check "fetch the scene by name" "$BIN" fetch --scene a --out "$WORK/scene-a" --server "$ADDR" --json
check "fetched every stage" test -s "$WORK/scene-a/decompose/labels.ply" -a -s "$WORK/scene-a/train/features.ply"
check "by name == by job id" cmp "$WORK/fetched/labels.ply" "$WORK/scene-a/segment/labels.ply"
check "jobs of a scene as a tree" "$BIN" jobs --server "$ADDR" --scene a
check "the tree nests train under decompose" grep -q "└ train" "$WORK/out.txt"
check "offline run" "$BIN" run --scene "$WORK/a" --out "$WORK/offline" --iterations 60 --samples 512 --pixel-pool 1024
check "service labels == offline labels" cmp "$WORK/fetched/labels.ply" "$WORK/offline/segmentation/labels.ply"
check "jobs table" "$BIN" jobs --server "$ADDR"
check "jobs table lists succeeded" grep -q "succeeded 3" "$WORK/out.txt"
check "jobs in pages of 2" "$BIN" jobs --server "$ADDR" --limit 2 --json
TOKEN=$(json_get "$WORK/out.txt" "d['next_page_token']")
check "a page token is given" test -n "$TOKEN"
check "the next page" "$BIN" jobs --server "$ADDR" --limit 2 --page-token "$TOKEN" --json
check "the next page holds the oldest job" test "$(json_get "$WORK/out.txt" "[j['kind'] for j in d['jobs']]")" = "['decompose']"
check_fails "a malformed page token" "INVALID_ARGUMENT" "$BIN" jobs --server "$ADDR" --page-token nope

# 2. Resubmitting computes nothing new and uploads nothing.
check "resubmit" "$BIN" submit --scene "$WORK/a" --server "$ADDR" --params "$SMALL" $PIPE --json
cp "$WORK/out.txt" "$WORK/submit2.json"
check "resubmit uploads nothing" test "$(json_get "$WORK/submit2.json" "d['uploaded_files']")" = "0"
check "resubmit returns the same finished jobs" test \
  "$(json_get "$WORK/submit2.json" "[(j['id'], j['state'], j['created']) for j in d['jobs']]")" = \
  "[('$DEC', 'succeeded', False), ('$TRAIN', 'succeeded', False), ('$SEG', 'succeeded', False)]"
check "no job ran twice" test "$(job_field "$ADDR" "$TRAIN" attempts)" = "1"

# 3. Bad requests: the right status, nothing queued.
check_fails "bad parameter" "INVALID_ARGUMENT.*'iterations' must be an integer" \
  "$BIN" submit --scene "$WORK/a" --server "$ADDR" --params '{"train":{"iterations":"many"}}'
check_fails "--iterations -1 is refused, not defaulted" "INVALID_ARGUMENT.*iterations" \
  "$BIN" submit --scene "$WORK/a" --server "$ADDR" --iterations -1
check_fails "unknown stage parameter" "INVALID_ARGUMENT.*unknown parameter 'tau'" \
  "$BIN" submit --scene "$WORK/a" --server "$ADDR" --params '{"segment":{"tau":0.5}}'
check_fails "unknown job" "NOT_FOUND.*job jdoesnotexist" "$BIN" fetch jdoesnotexist --out "$WORK/x" --server "$ADDR"
check_fails "no server" "unreachable" "$BIN" jobs --server 127.0.0.1:1
check "bad requests queued nothing" test "$(json_get <("$BIN" jobs --server "$ADDR" --json) "len(d['jobs'])")" = "3"

# 4. Cancellation reaches a running job and its dependents.
check "submit scene B (long)" "$BIN" submit --scene "$WORK/b" --server "$ADDR" --iterations 100000 $PIPE --json
cp "$WORK/out.txt" "$WORK/submit3.json"
BTRAIN=$(json_get "$WORK/submit3.json" "d['jobs'][1]['id']")
BSEG=$(json_get "$WORK/submit3.json" "d['jobs'][2]['id']")
check "B training runs" wait_state "$ADDR" "$BTRAIN" running training
check "cancel running job" "$BIN" cancel "$BTRAIN" --server "$ADDR"
check_fails "watch reports the cancellation" "cancelled" "$BIN" watch "$BTRAIN" "$BSEG" --server "$ADDR"
check "cancelled job state" test "$(job_field "$ADDR" "$BTRAIN" state)" = "cancelled"
check "dependent cancelled" test "$(job_field "$ADDR" "$BSEG" state)" = "cancelled"

# 5. The server killed with SIGKILL mid-job and restarted: every job survives and finishes.
check "resubmit B with other parameters" "$BIN" submit --scene "$WORK/b" --server "$ADDR" --params "$SMALL" $PIPE --json
cp "$WORK/out.txt" "$WORK/submit4.json"
B4TRAIN=$(json_get "$WORK/submit4.json" "d['jobs'][1]['id']")
B4SEG=$(json_get "$WORK/submit4.json" "d['jobs'][2]['id']")
check "submit slow pipeline on A" "$BIN" submit --scene "$WORK/a" --server "$ADDR" --params "$(slow 4000)" $PIPE --json
cp "$WORK/out.txt" "$WORK/submit5.json"
SLOW=$(json_get "$WORK/submit5.json" "d['jobs'][1]['id']")
SLOWSEG=$(json_get "$WORK/submit5.json" "d['jobs'][2]['id']")
check "slow training runs" wait_state "$ADDR" "$SLOW" running training
kill -9 "$SERVE"; wait "$SERVE" 2>/dev/null
start serve2 "$WORK/ready" "$BIN" serve --data "$WORK/data" --listen 127.0.0.1:0 --ready-file "$WORK/ready" --lease-seconds 2 --drain-seconds 0
SERVE=$LAST_PID
ADDR=$(cat "$WORK/ready")
check "all 10 jobs survived the crash" test "$(json_get <("$BIN" jobs --server "$ADDR" --json) "len(d['jobs'])")" = "10"
check "after restart everything finishes" "$BIN" watch "$SLOWSEG" "$B4SEG" --server "$ADDR"
check "the interrupted job was retried once" test "$(job_field "$ADDR" "$SLOW" attempts)" = "2"
check "first pipeline untouched" test "$(job_field "$ADDR" "$SEG" state)/$(job_field "$ADDR" "$SEG" attempts)" = "succeeded/1"

# 6. SIGTERM with a zero drain deadline hands the running job back; it finishes after a restart.
check "submit another slow pipeline" "$BIN" submit --scene "$WORK/b" --server "$ADDR" --params "$(slow 4001)" $PIPE --json
cp "$WORK/out.txt" "$WORK/submit6.json"
DRAIN=$(json_get "$WORK/submit6.json" "d['jobs'][1]['id']")
check "it runs" wait_state "$ADDR" "$DRAIN" running training
check_fails "gc refuses a data directory a server holds" "FAILED_PRECONDITION" "$BIN" gc --data "$WORK/data"
kill -TERM "$SERVE"; wait "$SERVE"
check "serve exited cleanly on SIGTERM" test $? -eq 0
check "drain log" grep -q "draining" "$WORK/serve2.log"
# The store's garbage collection with the server stopped: every blob a job reaches stays (the
# next section serves the same data directory and fetches every stage of scene a).
check "gc, dry run" "$BIN" gc --data "$WORK/data" --dry-run --json
check "gc counted every job as a root" test "$(json_get "$WORK/out.txt" "d['jobs'] >= 10 and d['live_blobs'] > 0 and d['missing_manifests'] == 0")" = True
check "gc without a grace period" "$BIN" gc --data "$WORK/data" --grace-hours 0 --json

# 7. Workers as separate processes (each with a worker token); one killed with SIGKILL mid-job.
check "a worker token" "$BIN" token create --data "$WORK/data" --role worker --note "test workers" --out "$WORK/worker.token"
WT="--token-file $WORK/worker.token"
start store "$WORK/ready-store" "$BINDIR/instascene-store" --data "$WORK/data" --listen 127.0.0.1:0 --ready-file "$WORK/ready-store"
STORE=$(cat "$WORK/ready-store")
start scheduler "$WORK/ready-sched" "$BINDIR/instascene-scheduler" --data "$WORK/data" --listen 127.0.0.1:0 --ready-file "$WORK/ready-sched" --store "$STORE" --lease-seconds 2 $WT
SCHED=$(cat "$WORK/ready-sched")
check "the handed-back job is queued" test "$(job_field "$SCHED" "$DRAIN" state)" = "queued"
check "handed back, not failed" grep -q "handed back" <(job_field "$SCHED" "$DRAIN" error)
start trainer1 "$WORK/ready-t1" "$BINDIR/instascene-training" --data "$WORK/w1" --store "$STORE" --scheduler "$SCHED" --lease-seconds 2 --ready-file "$WORK/ready-t1" $WT
T1=$LAST_PID
check "worker 1 takes the job" wait_state "$SCHED" "$DRAIN" running training
kill -9 "$T1"; wait "$T1" 2>/dev/null
start trainer2 "$WORK/ready-t2" "$BINDIR/instascene-training" --data "$WORK/w2" --store "$STORE" --scheduler "$SCHED" --lease-seconds 2 --ready-file "$WORK/ready-t2" --cache-bytes 1 $WT
check "the killed worker's job is retried and succeeds" "$BIN" watch "$DRAIN" --server "$SCHED"
check "two attempts: the killed one and the successful one (the hand-back is free)" test "$(job_field "$SCHED" "$DRAIN" attempts)" = "2"
check "exactly one result recorded" test -n "$(job_field "$SCHED" "$DRAIN" output_manifest)"
DRAINSEG=$(json_get "$WORK/submit6.json" "d['jobs'][2]['id']")
check "its segment job runs on worker 2 too" "$BIN" watch "$DRAINSEG" --server "$SCHED"
check "worker 2's 1-byte input cache evicted what the next job did not need" grep -q "evicted" "$WORK/trainer2.log"

# 8. Per-object completion: the generation worker takes one complete job per segmented object; a
# degenerate object fails its own job permanently with a message, the others succeed.
start generator "$WORK/ready-g" "$BINDIR/instascene-generation" --data "$WORK/w3" --store "$STORE" --scheduler "$SCHED" --ready-file "$WORK/ready-g" $WT
# (The parameters of A's latest pipeline, so that `fetch --scene` shows its objects.)
check "submit A with completion" "$BIN" submit --scene "$WORK/a" --server "$SCHED" --store "$STORE" --params "$(slow 4000)" --json
cp "$WORK/out.txt" "$WORK/submit7.json"
COMPLETE=$(json_get "$WORK/submit7.json" "' '.join(j['id'] for j in d['jobs'] if j['kind'] == 'complete')")
"$BIN" watch $COMPLETE --server "$SCHED" >/dev/null 2>&1
STATES=$(for j in $COMPLETE; do job_field "$SCHED" "$j" state; done | sort | uniq -c | tr -s ' ')
check "every complete job finished" test -z "$(for j in $COMPLETE; do job_field "$SCHED" "$j" state; done | grep -v -e succeeded -e failed)"
check "some objects completed" grep -q succeeded <<<"$STATES"
for j in $COMPLETE; do
  if [ "$(job_field "$SCHED" "$j" state)" = failed ]; then
    check "a failed object says why" grep -q "degenerate\|seen by no real view" <<<"$(job_field "$SCHED" "$j" error)"
    check "and is not retried" test "$(job_field "$SCHED" "$j" attempts)" = "1"
  fi
done
check "fetch the scene with its objects" "$BIN" fetch --scene a --out "$WORK/scene-a2" --server "$SCHED" --store "$STORE" --json
check "one complete job per instance" test "$(echo $COMPLETE | wc -w)" = "$(python3 -c "import json,sys; print(len(json.load(open(sys.argv[1]))))" "$WORK/scene-a2/segment/instances.json")"
check "objects have manifests and meshes" test -n "$(ls "$WORK"/scene-a2/complete/*/manifest.json)" -a -n "$(ls "$WORK"/scene-a2/complete/*/mesh.ply)"

# 9. Tenants, tokens and TLS on a second embedded server: a client token sees its tenant's scenes
# only; revoked tokens stop working without a restart; plaintext clients cannot reach a TLS
# listener; with mutual TLS a client needs a certificate the server's CA signed.
unset INSTASCENE_TOKEN_FILE
pki() {  # a CA, and certificates it signs for the server (localhost / 127.0.0.1) and a client
  cd "$WORK" &&
  openssl req -x509 -newkey rsa:2048 -nodes -days 1 -subj /CN=test-ca -keyout ca.key -out ca.pem &&
  for who in server client; do
    openssl req -newkey rsa:2048 -nodes -subj "/CN=$who" -keyout $who.key -out $who.csr &&
    printf 'subjectAltName=DNS:localhost,IP:127.0.0.1\n' > $who.ext &&
    openssl x509 -req -in $who.csr -CA ca.pem -CAkey ca.key -CAcreateserial -days 1 -out $who.pem -extfile $who.ext || return 1
  done
}
check "test certificates" pki
start serve3 "$WORK/ready3" "$BIN" serve --data "$WORK/data3" --listen 127.0.0.1:0 --ready-file "$WORK/ready3" --workers decomposition --tls-cert "$WORK/server.pem" --tls-key "$WORK/server.key"
ADDR3=$(cat "$WORK/ready3")
TLS="--tls-ca $WORK/ca.pem"
check "tenant acme's token" "$BIN" token create --data "$WORK/data3" --tenant acme --note "acme robots" --out "$WORK/acme.token"
check "tenant beta's token" "$BIN" token create --data "$WORK/data3" --tenant beta --out "$WORK/beta.token"
ACME="--token-file $WORK/acme.token"; BETA="--token-file $WORK/beta.token"; ADMIN="--token-file $WORK/data3/auth/admin.token"
check "the token file holds no token" bash -c "! grep -q \"\$(cut -c18- '$WORK/acme.token')\" '$WORK/data3/auth/tokens.json'"
check "token list" "$BIN" token list --data "$WORK/data3" --json
check "three tokens listed" test "$(json_get "$WORK/out.txt" "len(d['tokens'])")" = "3"
check_fails "a plaintext client cannot talk to the TLS listener" "unreachable\|UNAVAILABLE" "$BIN" jobs --server "$ADDR3" $ADMIN
check_fails "no token: UNAUTHENTICATED" "UNAUTHENTICATED" bash -c "cd '$WORK' && '$BIN' jobs --server '$ADDR3' $TLS"
check "acme submits scene A" "$BIN" submit --scene "$WORK/a" --server "$ADDR3" --stages decompose $TLS $ACME --json
ACMEJOB=$(json_get "$WORK/out.txt" "d['jobs'][0]['id']")
check "acme's job finishes" "$BIN" watch "$ACMEJOB" --server "$ADDR3" $TLS $ACME
check "acme fetches its result" "$BIN" fetch "$ACMEJOB" --out "$WORK/acme-out" --server "$ADDR3" $TLS $ACME
check "acme sees its scene under its own name" test "$(json_get <("$BIN" jobs --server "$ADDR3" $TLS $ACME --json) "d['jobs'][0]['scene']")" = "a"
check "beta sees no job" test "$(json_get <("$BIN" jobs --server "$ADDR3" $TLS $BETA --json) "len(d['jobs'])")" = "0"
check_fails "beta cannot fetch acme's job" "NOT_FOUND" "$BIN" fetch "$ACMEJOB" --out "$WORK/beta-out" --server "$ADDR3" $TLS $BETA
check_fails "beta cannot cancel acme's job" "NOT_FOUND" "$BIN" cancel "$ACMEJOB" --server "$ADDR3" $TLS $BETA
check_fails "beta cannot fetch acme's scene" "NOT_FOUND" "$BIN" fetch --scene a --out "$WORK/beta-out" --server "$ADDR3" $TLS $BETA
check "the admin sees the stored name" test "$(json_get <("$BIN" jobs --server "$ADDR3" $TLS $ADMIN --json) "d['jobs'][0]['scene']")" = "acme:a"
check_fails "beta cannot delete acme's scene" "NOT_FOUND" "$BIN" delete --scene a --server "$ADDR3" $TLS $BETA
check "acme deletes its scene" "$BIN" delete --scene a --server "$ADDR3" $TLS $ACME --json
check "its one job deleted" test "$(json_get "$WORK/out.txt" "d['deleted_jobs']")" = 1
check "acme has no job left" test "$(json_get <("$BIN" jobs --server "$ADDR3" $TLS $ACME --json) "len(d['jobs'])")" = 0
ACMEID=$(cut -c5-16 "$WORK/acme.token")
check "revoke acme's token" "$BIN" token revoke "$ACMEID" --data "$WORK/data3"
revoked() {  # servers re-read the changed token file at the next call (polled: a kubelet may lag)
  for _ in $(seq 50); do
    grep -q UNAUTHENTICATED <<<"$("$BIN" jobs --server "$ADDR3" $TLS $ACME 2>&1)" && return 0; sleep 0.1
  done; return 1
}
check "the revoked token is refused without a restart" revoked
start serve4 "$WORK/ready4" "$BIN" serve --data "$WORK/data4" --listen 127.0.0.1:0 --ready-file "$WORK/ready4" --workers none --tls-cert "$WORK/server.pem" --tls-key "$WORK/server.key" --tls-client-ca "$WORK/ca.pem"
ADDR4=$(cat "$WORK/ready4")
ADMIN4="--token-file $WORK/data4/auth/admin.token"
check_fails "mutual TLS: no client certificate, no connection" "unreachable\|UNAVAILABLE" "$BIN" jobs --server "$ADDR4" $TLS $ADMIN4
check "mutual TLS: with the client certificate" "$BIN" jobs --server "$ADDR4" $TLS $ADMIN4 --tls-client-cert "$WORK/client.pem" --tls-client-key "$WORK/client.key"

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
