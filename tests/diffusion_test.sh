#!/usr/bin/env bash
# End-to-end test of the diffusion prior with a model file (issue 18): the analytic Gaussian
# denoiser written as ONNX by Debian's python3-onnx (tests/diffusion/analytic_denoiser_onnx.py)
# completes objects through `instascene complete --denoiser onnx:FILE.json` in process, through
# `instascene-denoiser` serving the same file (the same object bit for bit), and as complete jobs of
# a pipeline on `instascene serve --denoiser grpc://...`; a model answering NaN fails the complete
# jobs with the reason and no output; a model config that does not fit is refused up front.
# Prints "N passed, N failed"; exits 1 on any failure.
set -uo pipefail
BIN=$1     # the instascene command
BINDIR=$2  # folder with instascene-denoiser
SRC=$3     # the source tree
source "$(dirname "$0")/test_lib.sh"

model() {  # model NAME VARIANT: NAME.onnx and NAME.json for a [4, 32, 32] latent
  /usr/bin/python3 "$SRC/tests/diffusion/analytic_denoiser_onnx.py" "$WORK/$1.onnx" 4 32 32 0.16 "$2" &&
  printf '{"model": "%s.onnx", "name": "%s", "latent_shape": [4, 32, 32],
    "inputs": {"latent": "x", "alpha_bar": "alpha_bar", "condition_latent": "cond"},
    "output": "eps"}\n' "$1" "$1" > "$WORK/$1.json"
}
manifest_field() {  # manifest_field FILE EXPR
  python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print($2)" "$1"
}
check "the analytic denoiser as ONNX" model analytic plain
check "a model answering NaN" model poisoned nan
check "synth scene" "$BIN" synth --out "$WORK/s" --preset tiny --seed 5
COMPLETE=(complete --scene "$WORK/s" --result "$WORK/s/gt" --object 1 --mesh-size 64 --refine-iterations 5 --prior diffusion)

# 1. In process (OpenCV's DNN module) and behind the Denoiser service: the same object.
check "complete with onnx:FILE.json" "$BIN" "${COMPLETE[@]}" --denoiser "onnx:$WORK/analytic.json" --out "$WORK/onnx" --json
M1=$(ls "$WORK"/onnx/*/manifest.json | head -n 1)
check "the manifest names the diffusion prior" test "$(manifest_field "$M1" "d['prior']")" = "diffusion"
check "views were generated" test "$(manifest_field "$M1" "d['prior_report']['generated_cells'] > 0 and d['unknown_views'] > 0")" = "True"
start denoiser "$WORK/ready-d" "$BINDIR/instascene-denoiser" --onnx "$WORK/analytic.json" --listen 127.0.0.1:0 --ready-file "$WORK/ready-d"
DENOISER=$(cat "$WORK/ready-d")
check "complete through instascene-denoiser" "$BIN" "${COMPLETE[@]}" --denoiser "grpc://$DENOISER" --out "$WORK/grpc" --json
M2=$(ls "$WORK"/grpc/*/manifest.json | head -n 1)
check "the same object either way" cmp "$(dirname "$M1")/object.ply" "$(dirname "$M2")/object.ply"
check_fails "a config whose latent does not fit the prior" "latents are \[4, n, n\]" bash -c \
  "sed 's/\[4, 32, 32\]/[3, 32, 32]/' '$WORK/analytic.json' > '$WORK/three.json' && '$BIN' ${COMPLETE[*]} --denoiser onnx:$WORK/three.json --out '$WORK/x'"
check_fails "instascene-denoiser refuses a missing model" "no such file" "$BINDIR/instascene-denoiser" --onnx "$WORK/absent.json"

# 2. Complete jobs on workers started with --denoiser.
SMALL='{"train":{"iterations":60,"samples":512,"pixel_pool":1024},"complete":{"prior":"diffusion","mesh_size":64,"refine_iterations":5}}'
start serve "$WORK/ready" "$BIN" serve --data "$WORK/data" --listen 127.0.0.1:0 --ready-file "$WORK/ready" --denoiser "grpc://$DENOISER"
ADDR=$(cat "$WORK/ready")
export INSTASCENE_TOKEN_FILE="$WORK/data/auth/admin.token"
check "submit with the diffusion prior" "$BIN" submit --scene "$WORK/s" --server "$ADDR" --params "$SMALL" --stages decompose,train,segment,complete --json
JOBS=$(json_get "$WORK/out.txt" "' '.join(j['id'] for j in d['jobs'])")
"$BIN" watch $JOBS --server "$ADDR" >/dev/null 2>&1
check "every job succeeded" test -z "$(for j in $JOBS; do job_field "$ADDR" "$j" state; done | grep -v succeeded)"
check "fetch the scene" "$BIN" fetch --scene s --out "$WORK/fetched" --server "$ADDR" --json
check "its objects were completed by the diffusion prior" test -z "$(for m in "$WORK"/fetched/complete/*/manifest.json; do manifest_field "$m" "d['prior']"; done | grep -v diffusion)"
kill -TERM "$LAST_PID"; wait "$LAST_PID" 2>/dev/null

# 3. A model answering NaN: the complete jobs fail with the reason and leave no output.
start poisoned "$WORK/ready-p" "$BINDIR/instascene-denoiser" --onnx "$WORK/poisoned.json" --listen 127.0.0.1:0 --ready-file "$WORK/ready-p"
start serve2 "$WORK/ready2" "$BIN" serve --data "$WORK/data2" --listen 127.0.0.1:0 --ready-file "$WORK/ready2" --denoiser "grpc://$(cat "$WORK/ready-p")"
ADDR2=$(cat "$WORK/ready2")
export INSTASCENE_TOKEN_FILE="$WORK/data2/auth/admin.token"
check "submit to workers with a poisoned model" "$BIN" submit --scene "$WORK/s" --server "$ADDR2" --params "$SMALL" --stages decompose,train,segment,complete --json
FAILING=$(json_get "$WORK/out.txt" "' '.join(j['id'] for j in d['jobs'] if j['kind'] == 'complete')")
"$BIN" watch $FAILING --server "$ADDR2" >/dev/null 2>&1
for j in $FAILING; do
  check "complete job $j failed" test "$(job_field "$ADDR2" "$j" state)" = failed
  check "naming the bad answer" grep -q "not finite" <<<"$(job_field "$ADDR2" "$j" error)"
done
check "no failed job left an output" test -z "$("$BIN" jobs --server "$ADDR2" --json --limit 100 | tail -n 1 | python3 -c "import json,sys; print([j['id'] for j in json.load(sys.stdin)['jobs'] if j['state'] == 'failed' and 'output_manifest' in j])" | grep -v '^\[\]$')"

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
