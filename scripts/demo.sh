#!/usr/bin/env bash
# `make demo`: what the project can do today, end to end on this machine.
# 1. renders real trained splats from ../shared/data/splats from several viewpoints;
# 2. generates a synthetic cluttered scene with ground truth and noisy 2D masks;
# 3. starts the embedded server (`instascene serve`: store + scheduler + workers), submits that
#    scene and a composite of the real captures, watches their pipelines (decompose -> train ->
#    segment -> complete, one completion job per object; -> export for the synthetic scene),
#    resubmits to show nothing is recomputed;
# 4. fetches the per-instance results and the completed objects, scores both against the ground
#    truth (click mIoU; Chamfer / volume IoU / hidden-surface recall of raw crop, closed crop and
#    completed object), writes raw-vs-completed images from an unknown view;
# 5. fetches one object the way a robot would (by a 3D point, through the C++ client library's
#    example program): its pose, size in metres and artefacts; stops the server;
# then prints what it wrote and how long it took.
set -euo pipefail
BUILD_DIR=${1:-build}
BIN="$BUILD_DIR/clients/cli/instascene"
OUT=demo-out
SPLATS=../shared/data/splats
rm -rf "$OUT"
mkdir -p "$OUT/real"
start_ns=$(date +%s%N)

echo "== 1. Real trained splats (3DGS captures from ../shared/data/splats) =="
if [ -d "$SPLATS" ]; then
  for name in statue_massa statue_angel playbot_lod4_3dgs_order; do
    ply="$SPLATS/$name.ply"
    [ -f "$ply" ] || continue
    "$BIN" info --ply "$ply" --json | tail -n 1
    for az in 0 90 180 270; do
      "$BIN" render --ply "$ply" --orbit "$az,15" --width 640 --height 480 --out "$OUT/real/${name}_az${az}.png"
    done
    "$BIN" render --ply "$ply" --orbit "30,15" --width 640 --height 480 --mode depth --out "$OUT/real/${name}_depth.png"
    "$BIN" render --ply "$ply" --orbit "30,15" --width 640 --height 480 --surfels --mode normal --out "$OUT/real/${name}_surfel_normals.png"
  done
else
  echo "(no $SPLATS: skipping real splats)"
fi

echo "== 2. A synthetic cluttered scene with ground truth =="
# --unseen drop: surfaces no camera sees have no surfels, as in a model trained on the images
# (the parts in-situ completion must bring back).
"$BIN" synth --out "$OUT/synthetic" --preset small --seed 7 --unseen drop
"$BIN" info --scene "$OUT/synthetic"
for v in 0 11 23; do
  "$BIN" render --scene "$OUT/synthetic" --view "$v" --mode depth --out "$OUT/synthetic/depth_$v.png"
  "$BIN" render --scene "$OUT/synthetic" --view "$v" --mode normal --out "$OUT/synthetic/normal_$v.png"
done

if [ -d "$SPLATS" ]; then
  echo "-- and a composite of the real captures (three trained splats in one room, their 2D masks rendered)"
  "$BIN" synth --out "$OUT/composite" --from-splats "$SPLATS/statue_massa.ply,$SPLATS/playbot_lod4_3dgs_order.ply,$SPLATS/statue_angel.ply" \
    --views 24 --width 320 --height 240
fi

echo "== 3. The main job through the services (embedded default: store + scheduler + workers in one process) =="
"$BIN" serve --data "$OUT/server" --listen 127.0.0.1:0 --gateway 127.0.0.1:0 --ready-file "$OUT/server.addr" \
  >"$OUT/server.log" 2>&1 &
SERVER_PID=$!
trap 'kill -TERM $SERVER_PID 2>/dev/null || true' EXIT
for _ in $(seq 200); do [ -s "$OUT/server.addr" ] && break; sleep 0.05; done
ADDR=$(head -n 1 "$OUT/server.addr")
GATEWAY=$(sed -n 's/^gateway=//p' "$OUT/server.addr")
# On first start the server wrote an admin token beside its data; the clients below use it.
export INSTASCENE_TOKEN_FILE="$OUT/server/auth/admin.token"
echo "server: $ADDR (log: $OUT/server.log, data: $OUT/server/, admin token: $INSTASCENE_TOKEN_FILE)"
echo "web UI (while the demo runs; the link carries the admin token): http://$GATEWAY/#token=$(cat "$INSTASCENE_TOKEN_FILE")"
scenes=(synthetic)
[ -d "$OUT/composite" ] && scenes+=(composite)
# The synthetic scene (metric: meters_per_unit 1) also gets the robot-ready export of every object.
echo "-- submit synthetic (decompose -> train -> segment -> complete -> export)"
"$BIN" submit --scene "$OUT/synthetic" --server "$ADDR" --stages decompose,train,segment,complete,export \
  --json > "$OUT/synthetic.submit.json"
if [ -d "$OUT/composite" ]; then
  echo "-- submit composite"
  "$BIN" submit --scene "$OUT/composite" --server "$ADDR" --json > "$OUT/composite.submit.json"
fi
echo "-- watch (both scenes share the workers; the scheduler alternates between them)"
for scene in "${scenes[@]}"; do "$BIN" watch --scene "$scene" --server "$ADDR"; done
"$BIN" jobs --server "$ADDR" --scene synthetic
echo "-- resubmitting the same capture uploads and computes nothing:"
"$BIN" submit --scene "$OUT/synthetic" --server "$ADDR" --stages decompose,train,segment,complete,export 2>&1 | sed 's/^/  /'

echo "== 4. Results, fetched from the store by scene name (every stage's latest output) =="
for scene in "${scenes[@]}"; do
  "$BIN" fetch --scene "$scene" --out "$OUT/$scene/stages" --server "$ADDR"
  rm -rf "$OUT/$scene/result" && ln -s stages/segment "$OUT/$scene/result"
  "$BIN" eval --scene "$OUT/$scene" --result "$OUT/$scene/result" --json 2>/dev/null | tail -n 1 > "$OUT/$scene.eval.json"
  python3 - "$OUT/$scene" <<'PY'
import json, sys
d = sys.argv[1]
ev = json.load(open(d + ".eval.json"))
instances = json.load(open(d + "/result/instances.json"))
print(f"  {d}: {len(instances)} instances found ({len(ev['objects'])} objects in the ground truth); "
      f"click mIoU {ev['miou']:.3f}, 3D precision {ev['precision_3d']:.2f} / recall {ev['recall_3d']:.2f}")
PY
done
for v in 0 11 23; do
  "$BIN" render --scene "$OUT/synthetic" --view "$v" --mode labels --result "$OUT/synthetic/result" --out "$OUT/synthetic/instances_$v.png"
done
echo "-- completed objects (raw crop | completed, from the least-known ring view):"
for dir in "$OUT/synthetic/stages/complete"/*/; do
  item=$(basename "$dir")
  [ -f "$dir/views/compare_unknown.png" ] && cp "$dir/views/compare_unknown.png" "$OUT/synthetic/completion_$item.png"
done
"$BIN" eval --scene "$OUT/synthetic" --completion "$OUT/synthetic/stages/complete" | sed 's/^/  /'
echo "-- per-instance splats (open in any 3DGS viewer):"
ls "$OUT/synthetic/result/instances" | head -n 20 | sed 's/^/  /'

echo "== 5. A robot asks for the object at a 3D point (Objects service through the C++ client) =="
"$BIN" objects --scene synthetic --server "$ADDR" | sed 's/^/  /'
# The point: the top centre of a ground-truth object with a closed top (what a robot's depth camera
# would see), in the scene's frame.
POINT=$(python3 -c "
import json
objs = json.load(open('$OUT/synthetic/gt/objects.json'))
o = next(o for o in objs if o['shape'] in ('box', 'bottle', 'sphere', 'cylinder'))
print('%.4f %.4f %.4f' % ((o['bounds_min'][0] + o['bounds_max'][0]) / 2, (o['bounds_min'][1] + o['bounds_max'][1]) / 2, o['bounds_max'][2]))")
echo "-- clients/cpp/examples/object_at_point $ADDR synthetic $POINT $OUT/robot"
# shellcheck disable=SC2086
"$BUILD_DIR/clients/cpp/object_at_point" "$ADDR" synthetic $POINT "$OUT/robot" | sed 's/^/  /'
echo "== 6. The web UI's viewer with the objects of the synthetic scene (Chromium, headless) =="
if [ -f "$BUILD_DIR/web-build/node_modules/playwright-core/package.json" ] && command -v chromium >/dev/null; then
  HOME="$PWD/$OUT/.browser" node "$BUILD_DIR/web-build/tests/screenshot.mjs" "http://$GATEWAY" \
    "$(cat "$INSTASCENE_TOKEN_FILE")" synthetic "$OUT/viewer.png" | sed 's/^/  /' ||
    echo "  (the screenshot failed; the UI itself is at http://$GATEWAY/)"
  rm -rf "$OUT/.browser"
else
  echo "  (no web UI bundle or Chromium here: skipped)"
fi
kill -TERM $SERVER_PID
wait $SERVER_PID || true
trap - EXIT
echo "server stopped: $(tail -n 1 "$OUT/server.log")"

end_ns=$(date +%s%N)
echo
echo "== Demo output =="
echo "  demo-out/real/                         $(ls demo-out/real 2>/dev/null | wc -l) renders of the real captures (color, depth, surfel normals)"
echo "  demo-out/synthetic/                    scene: images/, masks/ (noisy), gt/ (ground truth)"
echo "  demo-out/synthetic/stages/             every stage's output, fetched by scene name (result/ links to stages/segment/: labels, instances/*.ply)"
echo "  demo-out/synthetic/instances_*.png     rendered instance maps"
echo "  demo-out/synthetic/completion_*.png    each object: raw crop | completed, seen from an unknown view"
echo "  demo-out/synthetic/stages/complete/    each completed object: object.ply (provenance), mesh.ply, manifest.json"
[ -d "$OUT/composite" ] && echo "  demo-out/composite/                    the real captures composed into one scene, and its result/"
echo "  demo-out/synthetic/stages/export/      each object robot-ready: visual.glb (Draco), object.urdf, object.xml (MJCF), collision/, points.ply, manifest.json"
echo "  demo-out/robot/                        the object a robot fetched by a 3D point (artefacts, digests verified)"
echo "  demo-out/viewer.png                    the web UI's viewer with the synthetic scene's objects (one selected)"
echo "  demo-out/server/                       the server's data: store/ (content-addressed blobs), jobs.db (SQLite queue)"
echo "  ($(find "$OUT" -name '*.png' | wc -l) PNG and $(find "$OUT" -name '*.ply' | wc -l) PLY files in all)"
elapsed_ms=$(( (end_ns - start_ns) / 1000000 ))
printf "Demo finished in %d.%03d s\n" $((elapsed_ms / 1000)) $((elapsed_ms % 1000))
