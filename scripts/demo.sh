#!/usr/bin/env bash
# `make demo`: what the project can do today, end to end on this machine.
# 1. renders real trained splats from ../shared/data/splats from several viewpoints;
# 2. generates a synthetic cluttered scene with ground truth and noisy 2D masks;
# 3. decomposes it into 3D instances (spatial Gaussian trackers + mask clustering) and scores the
#    result against the ground truth; also on a composite of the real captures;
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
"$BIN" synth --out "$OUT/synthetic" --preset small --seed 7
"$BIN" info --scene "$OUT/synthetic"
for v in 0 11 23; do
  "$BIN" render --scene "$OUT/synthetic" --view "$v" --mode depth --out "$OUT/synthetic/depth_$v.png"
  "$BIN" render --scene "$OUT/synthetic" --view "$v" --mode normal --out "$OUT/synthetic/normal_$v.png"
done

echo "== 3. The main job offline: noisy 2D masks -> 3D instances (decompose + train + segment) =="
"$BIN" run --scene "$OUT/synthetic" --out "$OUT/synthetic/run"
echo "-- coarse decomposition (labels):"
"$BIN" eval --scene "$OUT/synthetic" --result "$OUT/synthetic/run/decomposition" | tail -n 1
echo "-- full method (trained features, click protocol):"
"$BIN" eval --scene "$OUT/synthetic" --result "$OUT/synthetic/run/segmentation"
for v in 0 11 23; do
  "$BIN" render --scene "$OUT/synthetic" --view "$v" --mode labels --result "$OUT/synthetic/run/segmentation" --out "$OUT/synthetic/instances_$v.png"
done
echo "-- per-instance splats (open in any 3DGS viewer):"
ls "$OUT/synthetic/run/segmentation/instances" | head -n 20 | sed 's/^/  /' 
if [ -d "$SPLATS" ]; then
  "$BIN" synth --out "$OUT/composite" --from-splats "$SPLATS/statue_massa.ply,$SPLATS/playbot_lod4_3dgs_order.ply,$SPLATS/statue_angel.ply" \
    --views 24 --width 320 --height 240
  "$BIN" run --scene "$OUT/composite" --out "$OUT/composite/run"
  echo "-- real-capture composite, full method:"
  "$BIN" eval --scene "$OUT/composite" --result "$OUT/composite/run/segmentation" | tail -n 1
fi

end_ns=$(date +%s%N)
echo
echo "== Demo output =="
echo "  demo-out/real/                         $(ls demo-out/real 2>/dev/null | wc -l) renders of the real captures (color, depth, surfel normals)"
echo "  demo-out/synthetic/                    scene: images/, masks/ (noisy), gt/ (ground truth)"
echo "  demo-out/synthetic/run/decomposition/  coarse 3D instances, filtered and consistent 2D masks"
echo "  demo-out/synthetic/run/segmentation/   features, labels, instances/*.ply, scene_labelled.ply"
echo "  demo-out/synthetic/instances_*.png     rendered instance maps"
[ -d "$OUT/composite" ] && echo "  demo-out/composite/                    the real captures composed into one scene, and its run/"
echo "  ($(find "$OUT" -name '*.png' | wc -l) PNG and $(find "$OUT" -name '*.ply' | wc -l) PLY files in all)"
elapsed_ms=$(( (end_ns - start_ns) / 1000000 ))
printf "Demo finished in %d.%03d s\n" $((elapsed_ms / 1000)) $((elapsed_ms % 1000))
