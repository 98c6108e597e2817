#!/usr/bin/env bash
# Reproduces the feature-training table of docs/RESULTS.md (paper Table 2 on our scenes): for each
# scene, one decomposition, then every supervision variant and the vote baseline, each scored with
# `instascene eval` (click mIoU with features where the result has them).
# Usage: scripts/results_training.sh [BUILD_DIR] [WORK_DIR]
set -euo pipefail
BUILD_DIR=${1:-build}
WORK=${2:-$(mktemp -d)}
BIN="$BUILD_DIR/clients/cli/instascene"
miou() { "$BIN" eval --scene "$1" --result "$2" --json 2>/dev/null | tail -n 1 | python3 -c "import json,sys; print('%.3f' % json.load(sys.stdin)['miou'])"; }
scene_row() {  # scene_row LABEL SCENE
  local s=$2
  "$BIN" decompose --scene "$s" --out "$s/dec" >/dev/null 2>&1
  local cells="$(miou "$s" "$s/dec")"
  "$BIN" train --scene "$s" --decomposition "$s/dec" --out "$s/vote" --method vote >/dev/null 2>&1
  cells="$cells | $(miou "$s" "$s/vote")"
  for sup in noisy2d 3d 3d+filtered2d full; do
    "$BIN" train --scene "$s" --decomposition "$s/dec" --out "$s/train_$sup" --supervision "$sup" >/dev/null 2>&1
    cells="$cells | $(miou "$s" "$s/train_$sup")"
  done
  echo "| $1 | $cells |"
}
echo "| scene | decomposition labels | vote | noisy 2D | 3D | 3D + filtered 2D | full |"
echo "|---|---|---|---|---|---|---|"
for noise in low medium high; do
  for seed in 1 2 3; do
    "$BIN" synth --out "$WORK/s_${noise}_$seed" --preset small --seed "$seed" --mask-noise "$noise" >/dev/null 2>&1
    scene_row "small, $noise, seed $seed" "$WORK/s_${noise}_$seed"
  done
done
S=../shared/data/splats
if [ -d "$S" ]; then
  "$BIN" synth --out "$WORK/composite" --from-splats "$S/statue_massa.ply,$S/playbot_lod4_3dgs_order.ply,$S/statue_angel.ply" \
    --views 32 --width 320 --height 240 --mask-noise medium >/dev/null 2>&1
  scene_row "real composite, medium" "$WORK/composite"
fi
