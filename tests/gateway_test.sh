#!/usr/bin/env bash
# The HTTP gateway through `instascene serve --gateway`, driven by curl and Python's urllib as a
# browser's code would: health; the error model (JSON with the status name, HTTP codes of Google's
# mapping); authentication (bearer header, access_token for EventSource) and tenants; live job
# events as Server-Sent Events until the job ends; jobs, scenes, stages, queue; resumable blob
# uploads (Upload-Offset) and downloads with Range requests and content types; bounded bodies;
# deleting a scene.
# Prints "N passed, N failed"; exits 1 on any failure.
set -uo pipefail
BIN=$1     # the instascene command
BINDIR=$2  # folder with instascene-gateway
source "$(dirname "$0")/test_lib.sh"

check "synth" "$BIN" synth --out "$WORK/a" --preset tiny --seed 5
# No worker in the server: the first job waits queued until the stream is open (below).
start serve "$WORK/ready" "$BIN" serve --data "$WORK/data" --listen 127.0.0.1:0 --ready-file "$WORK/ready" \
  --gateway 127.0.0.1:0 --workers none
ADDR=$(head -n 1 "$WORK/ready")
GW=http://$(sed -n 's/^gateway=//p' "$WORK/ready")
export INSTASCENE_TOKEN_FILE="$WORK/data/auth/admin.token"
ADMIN=$(cat "$INSTASCENE_TOKEN_FILE")
check "a tenant's token" "$BIN" token create --data "$WORK/data" --tenant beta --out "$WORK/beta.token"
BETA=$(cat "$WORK/beta.token")
H="Authorization: Bearer $ADMIN"
# http METHOD PATH [curl args...]: body to $WORK/body, status code to $WORK/code, headers to $WORK/headers
http() {
  local method=$1 path=$2; shift 2
  curl -s -X "$method" -o "$WORK/body" -D "$WORK/headers" -w '%{http_code}' "$@" "$GW$path" >"$WORK/code"
}
code() { cat "$WORK/code"; }
body() { python3 -c "import json,sys; d=json.load(open('$WORK/body')); print($1)"; }

check "health" http GET /api/v1/health
check "health is 200" test "$(code)" = 200
http GET /api/v1/jobs
check "no token: 401" test "$(code)" = 401
check "with the status name" test "$(body "d['error']['status']")" = UNAUTHENTICATED
http GET /api/v1/nowhere -H "$H"
check "unknown endpoint: 404 JSON" test "$(code)/$(body "d['error']['status']")" = 404/NOT_FOUND
http GET /api/v1/queue -H "Authorization: Bearer $BETA"
check "monitoring is for admins: 403" test "$(code)/$(body "d['error']['status']")" = 403/PERMISSION_DENIED
http POST /api/v1/pipelines -H "$H" --data '{"scene": 3'
check "malformed JSON body: 400" test "$(code)/$(body "d['error']['status']")" = 400/INVALID_ARGUMENT
head -c 9000000 /dev/zero >"$WORK/big"
OCTET="Content-Type: application/octet-stream"
http PUT "/api/v1/blobs/$(printf '0%.0s' {1..64})/9000000" -H "$H" -H "$OCTET" --data-binary @"$WORK/big"
check "a body over the limit: 413" test "$(code)/$(body "d['error']['code']")" = 413/413

# A pipeline submitted through gRPC, followed through the gateway.
check "submit" "$BIN" submit --scene "$WORK/a" --server "$ADDR" --stages decompose --json
JOB=$(json_get "$WORK/out.txt" "d['jobs'][0]['id']")
curl -s -N --max-time 120 "$GW/api/v1/events?job_ids=$JOB&access_token=$ADMIN" >"$WORK/events.txt" &
CURL=$!
for _ in $(seq 100); do grep -q "^event: job" "$WORK/events.txt" && break; sleep 0.05; done
check "the stream shows the job queued" grep -q '"state":"JOB_STATE_QUEUED"' "$WORK/events.txt"
# A decomposition worker as its own process now takes the job: its changes arrive live.
check "a worker token" "$BIN" token create --data "$WORK/data" --role worker --out "$WORK/worker.token"
start worker "$WORK/ready-worker" "$BINDIR/instascene-decomposition" --data "$WORK/worker" --scheduler "$ADDR" \
  --store "$ADDR" --token-file "$WORK/worker.token" --ready-file "$WORK/ready-worker"
wait $CURL
check "events end with an end event" grep -q "^event: end" "$WORK/events.txt"
check "the last job event says succeeded" test "$(grep '^data: {"id"' "$WORK/events.txt" | tail -n 1 | cut -c7- | python3 -c "import json,sys; print(json.load(sys.stdin)['state'])")" = JOB_STATE_SUCCEEDED
check "more than one event (live progress)" test "$(grep -c '^event: job' "$WORK/events.txt")" -ge 2
http GET "/api/v1/events?job_ids=$JOB"
check "events without a token: 401" test "$(code)" = 401
http GET "/api/v1/jobs?scene=a&state=succeeded" -H "$H"
check "jobs of scene a" test "$(code)/$(body "len(d['jobs'])")" = 200/1
http GET "/api/v1/jobs/$JOB" -H "$H"
check "one job" test "$(body "d['kind']")" = decompose
http GET "/api/v1/jobs/$JOB" -H "Authorization: Bearer $BETA"
check "another tenant's job: 404" test "$(code)/$(body "d['error']['status']")" = 404/NOT_FOUND
http GET /api/v1/scenes/a -H "$H"
check "the scene's outputs" test "$(body "d['outputs'][0]['kind']")" = decompose
HASH=$(body "d['outputs'][0]['output_manifest']['hash']"); SIZE=$(body "d['outputs'][0]['output_manifest']['size_bytes']")
http GET "/api/v1/blobs/$HASH/$SIZE?name=manifest.json" -H "$H"
check "download: 200, JSON content type" test "$(code)" = 200 -a -n "$(grep -i '^content-type: application/json' "$WORK/headers")"
check "download: the digest matches" test "$(sha256sum <"$WORK/body" | cut -c1-64)" = "$HASH"
http GET "/api/v1/blobs/$HASH/$SIZE" -H "$H" -H "Range: bytes=5-14"
check "range request: 206 with 10 bytes" test "$(code)/$(stat -c %s "$WORK/body")" = 206/10
check "range request: Content-Range" grep -qi "^content-range: bytes 5-14/$SIZE" "$WORK/headers"
http GET "/api/v1/blobs/$HASH/$SIZE" -H "Authorization: Bearer $BETA"
check "another tenant's blob: 404" test "$(code)" = 404
http GET /api/v1/stages -H "Authorization: Bearer $BETA"
check "stages for a client" test "$(code)" = 200

# A resumable upload in two chunks (Upload-Offset), as a browser uploading a capture would.
head -c 3000000 /dev/urandom >"$WORK/blob"
BH=$(sha256sum <"$WORK/blob" | cut -c1-64)
head -c 1000000 "$WORK/blob" >"$WORK/part1"; tail -c 2000000 "$WORK/blob" >"$WORK/part2"
http POST /api/v1/blobs/missing -H "Authorization: Bearer $BETA" --data "{\"digests\": [{\"hash\": \"$BH\", \"size_bytes\": 3000000}]}"
check "missing before the upload" test "$(body "len(d['missing'])")" = 1
http PUT "/api/v1/blobs/$BH/3000000" -H "Authorization: Bearer $BETA" -H "Upload-Offset: 0" -H "$OCTET" --data-binary @"$WORK/part1"
check "first chunk" test "$(code)/$(body "d['committed_size']")" = 200/1000000
http GET "/api/v1/blobs/$BH/3000000/status" -H "Authorization: Bearer $BETA"
check "status says where to resume" test "$(body "d['committed_size']")/$(body "d['complete']")" = 1000000/False
http PUT "/api/v1/blobs/$BH/3000000" -H "Authorization: Bearer $BETA" -H "Upload-Offset: 5" -H "$OCTET" --data-binary @"$WORK/part2"
check "a chunk at the wrong offset: 400 naming the committed size" grep -q "1000000 bytes committed" "$WORK/body"
http PUT "/api/v1/blobs/$BH/3000000" -H "Authorization: Bearer $BETA" -H "Upload-Offset: 1000000" -H "$OCTET" --data-binary @"$WORK/part2"
check "last chunk finishes the blob" test "$(code)" = 200
http GET "/api/v1/blobs/$BH/3000000" -H "Authorization: Bearer $BETA"
check "the tenant reads it back" cmp -s "$WORK/body" "$WORK/blob"
http GET "/api/v1/blobs/$BH/3000000" -H "Authorization: Bearer $ADMIN"
check "admins see every blob" test "$(code)" = 200
# A scene folder uploaded as a browser does: digests of every file, scene.json first, then the
# scene manifest (only the files scene.json references), the missing blobs, the pipeline.
python3 - "$WORK/a" >"$WORK/files.json" <<'PY'
import hashlib, json, os, sys
root = sys.argv[1]
files = {}
for d, _, names in os.walk(root):
    for n in names:
        p = os.path.join(d, n)
        files[os.path.relpath(p, root)] = {"hash": hashlib.sha256(open(p, "rb").read()).hexdigest(), "size_bytes": os.path.getsize(p)}
print(json.dumps({"files": files}))
PY
BT="Authorization: Bearer $BETA"
SJ=$(sha256sum <"$WORK/a/scene.json" | cut -c1-64); SJS=$(stat -c %s "$WORK/a/scene.json")
http POST /api/v1/scene-manifests -H "$BT" --data @"$WORK/files.json"
check "scene manifest before scene.json is uploaded: 400 saying so" test "$(code)/$(body "d['error']['status']")" = 400/FAILED_PRECONDITION -a -n "$(grep 'upload it first' "$WORK/body")"
http PUT "/api/v1/blobs/$SJ/$SJS" -H "$BT" -H "$OCTET" --data-binary @"$WORK/a/scene.json"
check "scene.json uploaded" test "$(code)" = 200
http POST /api/v1/scene-manifests -H "$BT" --data @"$WORK/files.json"
check "the scene manifest: 200" test "$(code)" = 200
check "it keeps only what scene.json references (no ground truth)" test "$(body "sum(1 for p in d['files'] if p.startswith('gt/'))")/$(body "'scene.json' in d['files']")" = 0/True
check "everything but scene.json is missing" test "$(body "len(d['missing'])")" = "$(body "len(d['files']) - 1")"
cp "$WORK/body" "$WORK/plan.json"
python3 - "$WORK/plan.json" "$WORK/a" "$GW" "$BETA" <<'PY' >"$WORK/sent.txt"
import json, sys, urllib.request
plan, root, gw, token = json.load(open(sys.argv[1])), sys.argv[2], sys.argv[3], sys.argv[4]
for path in plan["missing"]:
    d = plan["files"][path]
    req = urllib.request.Request(f"{gw}/api/v1/blobs/{d['hash']}/{d['size_bytes']}", data=open(f"{root}/{path}", "rb").read(), method="PUT",
                                 headers={"Authorization": f"Bearer {token}", "Content-Type": "application/octet-stream", "Upload-Offset": "0"})
    urllib.request.urlopen(req).read()
print(len(plan["missing"]))
PY
check "the missing files uploaded" test "$(cat "$WORK/sent.txt")" -ge 2
http POST /api/v1/pipelines -H "$BT" --data "{\"scene\": \"browser\", \"stages\": [\"decompose\"], \"scene_manifest\": $(python3 -c "import json; print(json.dumps(json.load(open('$WORK/plan.json'))['scene_manifest']))")}"
check "the pipeline submitted with the manifest" test "$(code)/$(body "d['jobs'][0]['scene']")" = 200/browser
python3 -c "import json; d=json.load(open('$WORK/files.json')); del d['files']['images/' + sorted(p for p in d['files'] if p.startswith('images/'))[0].split('/',1)[1]]; print(json.dumps(d))" >"$WORK/less.json"
http POST /api/v1/scene-manifests -H "$BT" --data @"$WORK/less.json"
check "a referenced file left out: 400 naming it" test "$(code)" = 400 -a -n "$(grep "scene.json refers to 'images/" "$WORK/body")"
http POST /api/v1/scene-manifests -H "$BT" --data '{"files": {"../scene.json": {"hash": "'"$SJ"'", "size_bytes": 1}}}'
check "an unsafe path: 400" test "$(code)/$(body "d['error']['status']")" = 400/INVALID_ARGUMENT
http POST /api/v1/scene-manifests -H "$BT" --data '{"files": []}'
check "a malformed body: 400" test "$(code)/$(body "d['error']['status']")" = 400/INVALID_ARGUMENT

# A browser that goes away mid-stream does not hold anything up.
check "submit a longer job" "$BIN" submit --scene "$WORK/a" --server "$ADDR" --stages decompose --params '{"decompose":{"min_tracker_gaussians":2}}' --json
JOB2=$(json_get "$WORK/out.txt" "d['jobs'][0]['id']")
curl -s -N --max-time 0.3 "$GW/api/v1/events?job_ids=$JOB2&access_token=$ADMIN" >/dev/null
check "the job still finishes" "$BIN" watch "$JOB2" --server "$ADDR"
check "the gateway still answers" http GET /api/v1/health

# The gateway as its own process, in front of the same server.
start gateway "$WORK/ready-gw" "$BINDIR/instascene-gateway" --listen 127.0.0.1:0 --scheduler "$ADDR" --ready-file "$WORK/ready-gw"
GW=http://$(cat "$WORK/ready-gw")
http GET "/api/v1/jobs/$JOB" -H "$H"
check "instascene-gateway answers like the embedded one" test "$(code)/$(body "d['id']")" = "200/$JOB"

# Deleting a scene whose jobs ended: a tenant's "a" is its own (none: 404), the admin's goes.
http DELETE /api/v1/scenes/a -H "Authorization: Bearer $BETA"
check "a tenant deleting a scene it has not: 404" test "$(code)/$(body "d['error']['status']")" = 404/NOT_FOUND
http DELETE /api/v1/scenes/a -H "$H"
check "the admin deletes scene a: 200, its jobs" test "$(code)/$(body "int(d['deleted_jobs']) >= 2")" = 200/True
http GET "/api/v1/jobs?scene=a" -H "$H"
check "no job of scene a left" test "$(body "len(d.get('jobs', []))")" = 0

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
