#!/usr/bin/env bash
# Reproduces the decomposition table of docs/RESULTS.md: synthetic `small` scenes at every mask-noise
# level (3 seeds each) and a composite of the real captures in ../shared/data/splats.
# Usage: scripts/results_decompose.sh [BUILD_DIR] [WORK_DIR]
set -euo pipefail
BUILD_DIR=${1:-build}
WORK=${2:-$(mktemp -d)}
BIN="$BUILD_DIR/clients/cli/instascene"
row() {  # row LABEL SCENE
  "$BIN" decompose --scene "$2" --out "$2/dec" --json 2>/dev/null | tail -n 1 > "$2/dec.json"
  "$BIN" eval --scene "$2" --result "$2/dec" --json 2>/dev/null | tail -n 1 > "$2/eval.json"
  python3 - "$1" "$2" <<'PY'
import json, sys
label, d = sys.argv[1], sys.argv[2]
dec, ev = json.load(open(d + "/dec.json")), json.load(open(d + "/eval.json"))
print(f"| {label} | {len(ev['objects'])} | {dec['instances']} | {ev['precision_3d']:.3f} | {ev['recall_3d']:.3f} | "
      f"{ev['mean_best_iou_3d']:.3f} | {ev['ari']:.3f} | {ev['miou']:.3f} | {dec['seconds']:.1f} |")
PY
}
echo "| scene | objects | instances | 3D precision@0.5 | 3D recall@0.5 | mean best IoU | ARI | click mIoU (labels) | decompose s |"
echo "|---|---|---|---|---|---|---|---|---|"
for noise in none low medium high; do
  for seed in 1 2 3; do
    "$BIN" synth --out "$WORK/small_${noise}_$seed" --preset small --seed "$seed" --mask-noise "$noise" 2>/dev/null
    row "small, $noise, seed $seed" "$WORK/small_${noise}_$seed"
  done
done
S=../shared/data/splats
if [ -d "$S" ]; then
  for noise in none medium; do
    "$BIN" synth --out "$WORK/composite_$noise" --from-splats "$S/statue_massa.ply,$S/playbot_lod4_3dgs_order.ply,$S/statue_angel.ply" \
      --views 32 --width 320 --height 240 --mask-noise "$noise" 2>/dev/null
    row "real composite (massa, playbot, angel), $noise" "$WORK/composite_$noise"
  done
fi
