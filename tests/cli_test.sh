#!/usr/bin/env bash
# End-to-end test of the instascene CLI: synth -> info -> render (every mode) -> import, plus the
# error contract (non-zero exit, one-line reason) on bad input. Prints "N passed, N failed".
set -uo pipefail
BIN=$1
SHARED=${2:-../shared}
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
passed=0
failed=0
check() {  # check NAME COMMAND...: the command must succeed
  local name=$1; shift
  if "$@" >"$WORK/cmd.txt" 2>"$WORK/err.txt"; then passed=$((passed + 1)); cp "$WORK/cmd.txt" "$WORK/out.txt"; else
    failed=$((failed + 1)); echo "FAIL: $name"; cat "$WORK/err.txt"; fi
}
check_fails() {  # check_fails NAME PATTERN COMMAND...: must fail with PATTERN on stderr
  local name=$1 pattern=$2; shift 2
  if "$@" >"$WORK/cmd.txt" 2>"$WORK/err.txt"; then failed=$((failed + 1)); echo "FAIL (succeeded): $name"
  elif grep -q "$pattern" "$WORK/err.txt"; then passed=$((passed + 1)); else
    failed=$((failed + 1)); echo "FAIL (wrong message): $name"; cat "$WORK/err.txt"; fi
}

check "synth tiny" "$BIN" synth --out "$WORK/s" --preset tiny --seed 3 --json
# The JSON's count is the PLY's (8000 requested, plus the table refined near objects).
check "synth json contract" bash -c "n=\$(grep -a -m1 'element vertex' '$WORK/s/gaussians.ply' | cut -d' ' -f3) && [ \"\$n\" -ge 8000 ] && tail -n 1 '$WORK/out.txt' | grep -q \"\\\"gaussians\\\":\$n[,}]\""
check "info" "$BIN" info --scene "$WORK/s" --json
check "info json" bash -c "tail -n 1 '$WORK/out.txt' | grep -q '\"masks\":12'"
check "gt masks written" test -s "$WORK/s/gt/masks/0011.png"
check_fails "bad noise level" "mask-noise" "$BIN" synth --out "$WORK/bad" --mask-noise extreme
for mode in color depth normal alpha; do
  check "render $mode" "$BIN" render --scene "$WORK/s" --view 0003 --mode "$mode" --out "$WORK/$mode.png"
  check "render $mode wrote png" test -s "$WORK/$mode.png"
done
check "render by index" "$BIN" render --scene "$WORK/s" --view 5 --out "$WORK/v5.png"
check "eval ground truth" "$BIN" eval --scene "$WORK/s" --result "$WORK/s/gt" --json
check "eval gt scores 1" bash -c "tail -n 1 '$WORK/out.txt' | grep -q '\"miou\":1.0'"
check_fails "eval without result" "no such file" "$BIN" eval --scene "$WORK/s" --result "$WORK/nothing"
check "run (decompose + train + segment + complete)" "$BIN" run --scene "$WORK/s" --out "$WORK/run" --iterations 60 --samples 512 --pixel-pool 1024 --json
check "run completed objects" test -s "$(ls "$WORK"/run/objects/*/manifest.json | head -n 1)"
check "run wrote instances" test -s "$WORK/run/segmentation/instances.json"
check "run wrote labelled scene" test -s "$WORK/run/segmentation/scene_labelled.ply"
check "eval trained features" "$BIN" eval --scene "$WORK/s" --result "$WORK/run/segmentation" --json
check "eval used features" bash -c "tail -n 1 '$WORK/out.txt' | grep -q '\"mode\":\"features\"'"
check "render labels" "$BIN" render --scene "$WORK/s" --view 2 --mode labels --result "$WORK/run/segmentation" --out "$WORK/labels.png"
# In-situ completion on a scene whose unseen surfels are dropped, scored against the truth.
check "synth with unseen surfels dropped" "$BIN" synth --out "$WORK/u" --preset tiny --seed 5 --unseen drop --mask-noise none
check "fewer surfels than the full scene" test "$(python3 -c "import json; print(json.load(open('$WORK/u/scene.json'))['gt']['unseen_surfels'])")" = dropped
check "complete the ground-truth objects (with 20 refinement iterations)" "$BIN" complete --scene "$WORK/u" --result "$WORK/u/gt" --out "$WORK/u/objects" --mesh-size 64 --refine-iterations 20 --json
check "completion json lists objects" bash -c "tail -n 1 '$WORK/out.txt' | grep -q '\"objects\":\[{'"
check "the refinement ran on real and generated views" python3 -c "
import glob, json
ms = [json.load(open(p))['refinement'] for p in glob.glob('$WORK/u/objects/*/manifest.json')]
assert ms and all(m['status'] == 'done' and m['iterations'] == 20 and m['generated_views'] == 16 for m in ms), ms
assert sum(m['real_views'] for m in ms) > 0, ms  # small objects at 96x72 may show < 64 px"
check "eval --completion" "$BIN" eval --scene "$WORK/u" --completion "$WORK/u/objects" --json
check "eval --completion reports three versions" bash -c "tail -n 1 '$WORK/out.txt' | python3 -c \"import json,sys; d=json.load(sys.stdin); assert d['matched'] > 0 and set(d['mean']) == {'raw','closed','completed'}\""
# Without a prior and without refinement the completed object is the raw crop, so the evaluation's
# closed crop (meshed again from the manifest, the visual hull carved from the scene's splats) must
# be the very same mesh.
check "complete without a prior or refinement" "$BIN" complete --scene "$WORK/u" --result "$WORK/u/gt" --out "$WORK/u/none" --mesh-size 64 --refine-iterations 0 --prior none
check "eval --completion of the closed crops" "$BIN" eval --scene "$WORK/u" --completion "$WORK/u/none" --json
check "the closed crop is meshed exactly as the completion meshed it" bash -c "tail -n 1 '$WORK/out.txt' | python3 -c \"import json,sys; os=json.load(sys.stdin)['objects']; assert os and all(o['closed']['volume_iou'] == o['completed']['volume_iou'] for o in os), [(o['closed']['volume_iou'], o['completed']['volume_iou']) for o in os]\""
mkdir -p "$WORK/u/broken" && cp -r "$(ls -d "$WORK"/u/objects/*/ | head -n 1)" "$WORK/u/broken/1" && echo '{"id": 1}' > "$WORK/u/broken/1/manifest.json"
check_fails "eval --completion on a malformed manifest" "malformed JSON field" "$BIN" eval --scene "$WORK/u" --completion "$WORK/u/broken"
check_fails "complete with an unknown prior" "magic" "$BIN" complete --scene "$WORK/u" --result "$WORK/u/gt" --out "$WORK/u/x" --prior magic
check_fails "the diffusion prior without a denoiser" "needs --denoiser grpc://HOST:PORT" "$BIN" complete --scene "$WORK/u" --result "$WORK/u/gt" --out "$WORK/u/x" --prior diffusion
check_fails "complete an absent object" "no object could be completed" "$BIN" complete --scene "$WORK/u" --result "$WORK/u/gt" --out "$WORK/u/y" --object 999
check_fails "eval needs exactly one of --result and --completion" "exactly one" "$BIN" eval --scene "$WORK/u" --result "$WORK/u/gt" --completion "$WORK/u/objects"
check "segment again" "$BIN" segment --scene "$WORK/s" --features "$WORK/run/segmentation" --out "$WORK/seg2" --threshold 0.8
check "segment from the coarse instances of the decomposition" "$BIN" segment --scene "$WORK/s" --features "$WORK/run/segmentation" --decomposition "$WORK/run/decomposition" --out "$WORK/seg4"
check "which reproduces the run's segmentation" cmp "$WORK/seg4/labels.ply" "$WORK/run/segmentation/labels.ply"
check_fails "segment from another scene's decomposition" "labels for" "$BIN" segment --scene "$WORK/s" --features "$WORK/run/segmentation" --decomposition "$WORK/u/gt" --out "$WORK/seg5"
check "and it wrote nothing" test ! -e "$WORK/seg5"
check "run with HDBSCAN labelling" "$BIN" run --scene "$WORK/s" --out "$WORK/runh" --stages decompose,train,segment --iterations 30 --samples 256 --pixel-pool 512 --labelling hdbscan
check "the segment stage labelled by HDBSCAN" python3 -c "
import json
r = json.load(open('$WORK/runh/segmentation/result.json'))
assert r['labelling'] == 'hdbscan' and 'hdbscan' in r and 'max_growth' not in r, r"
check "the decomposition labelled untraced Gaussians" python3 -c "
import json
assert json.load(open('$WORK/runh/decomposition/decomposition.json'))['untraced_labelled'] > 0"
check "train on the decomposition" "$BIN" train --scene "$WORK/s" --decomposition "$WORK/run/decomposition" --out "$WORK/tr" --iterations 30 --samples 256 --pixel-pool 512 --supervision 3d
check_fails "bad supervision" "supervision" "$BIN" train --scene "$WORK/s" --decomposition "$WORK/run/decomposition" --out "$WORK/tr" --supervision bogus
check_fails "segment without features" "no features" "$BIN" segment --scene "$WORK/s" --features "$WORK/s/gt" --out "$WORK/seg3"
check "query a pixel" "$BIN" query --scene "$WORK/s" --result "$WORK/run/segmentation" --view 3 --pixel 40,40 --out "$WORK/q" --json
check "query a point" "$BIN" query --scene "$WORK/s" --result "$WORK/s/gt" --point 0,0,0.8 --json
check "query a ray" "$BIN" query --scene "$WORK/s" --result "$WORK/s/gt" --ray 0,-1,1.2,0,1,-0.4 --json
check_fails "query outside the image" "outside" "$BIN" query --scene "$WORK/s" --result "$WORK/s/gt" --view 3 --pixel 4000,1
check "help" "$BIN" --help
check "render help" "$BIN" render --help
check_fails "missing scene" "no such file" "$BIN" info --scene "$WORK/nope"
check_fails "bad view" "no view named" "$BIN" render --scene "$WORK/s" --view 99 --out "$WORK/x.png"
check_fails "bad mode" "unknown --mode" "$BIN" render --scene "$WORK/s" --mode bogus --out "$WORK/x.png"
head -c 300 "$WORK/s/gaussians.ply" > "$WORK/trunc.ply"
check_fails "truncated ply" "truncated" "$BIN" info --ply "$WORK/trunc.ply"
check_fails "features without channels" "no 'segfeat_" "$BIN" render --scene "$WORK/s" --mode features --out "$WORK/x.png"

if [ -d "$SHARED/data/splats" ]; then
  check "render real splat" "$BIN" render --ply "$SHARED/data/splats/playbot_lod6.ply" --orbit 45,20 --width 64 --height 48 --out "$WORK/real.png"
  check "render real splat as surfels" "$BIN" render --ply "$SHARED/data/splats/playbot_lod6.ply" --surfels --mode normal --width 64 --height 48 --out "$WORK/real_n.png"
  check "composite of real splats" "$BIN" synth --out "$WORK/comp" --from-splats "$SHARED/data/splats/playbot_lod6.ply,$SHARED/data/splats/playbot_lod6_3dgs_order.ply" --views 6 --width 64 --height 48 --mask-noise low
  check "composite gt evaluates to 1" bash -c "'$BIN' eval --scene '$WORK/comp' --result '$WORK/comp/gt' --json | tail -n 1 | grep -q '\"miou\":1.0'"
  # A real SuperSplat compressed PLY (shared data: 90,854 Gaussians) loads and renders.
  check "compressed ply: info" bash -c "'$BIN' info --ply '$SHARED/data/splats/originals/guitar.compressed.ply' --json | tail -n 1 | grep -q '\"gaussians\":90854'"
  check "compressed ply: render" "$BIN" render --ply "$SHARED/data/splats/originals/guitar.compressed.ply" --orbit 30,15 --width 64 --height 48 --out "$WORK/guitar.png"
fi
if [ -d "$SHARED/data/fox_instant_ngp" ]; then
  check_fails "fox needs undistortion flag" "distortion" "$BIN" import --transforms "$SHARED/data/fox_instant_ngp/transforms_images_2.json" --ply "$WORK/s/gaussians.ply" --out "$WORK/fox"
  check "import fox" "$BIN" import --transforms "$SHARED/data/fox_instant_ngp/transforms_images_2.json" --ply "$WORK/s/gaussians.ply" --out "$WORK/fox" --assume-undistorted
  check "fox has 50 views" bash -c "'$BIN' info --scene '$WORK/fox' --json | tail -n 1 | grep -q '\"views\":50'"
  check "fox is unscaled" test "$(python3 -c "import json; print('meters_per_unit' in json.load(open('$WORK/fox/scene.json')))")" = False
  check "import with a metric scale" "$BIN" import --transforms "$SHARED/data/fox_instant_ngp/transforms_images_2.json" --ply "$WORK/s/gaussians.ply" --out "$WORK/fox_m" --assume-undistorted --meters-per-unit 0.25
  check "the scale is in scene.json" test "$(python3 -c "import json; print(json.load(open('$WORK/fox_m/scene.json'))['meters_per_unit'])")" = 0.25
  check_fails "a non-positive scale is refused" "meters-per-unit" "$BIN" import --transforms "$SHARED/data/fox_instant_ngp/transforms_images_2.json" --ply "$WORK/s/gaussians.ply" --out "$WORK/fox_bad" --assume-undistorted --meters-per-unit -1
  check_fails "eval needs ground truth" "no ground truth" "$BIN" eval --scene "$WORK/fox" --result "$WORK/s/gt"
fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
