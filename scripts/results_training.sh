#!/usr/bin/env bash
# Reproduces the feature-training table of docs/RESULTS.md (paper Table 2 on our scenes): for each
# scene, one decomposition, then every supervision variant and the vote baseline, each scored with
# `instascene eval` (click mIoU with features where the result has them, on labels otherwise); the
# full variant is also scored on its final labels, from the tau rule (`train`'s default) and from
# HDBSCAN (`segment --labelling hdbscan`, from the decomposition's coarse instances), with `eval
# --labels-only`. Scenes: the `small` preset
# under the noise family the constants were developed on (low, medium, high) and under the held-back
# part-aware family (sam-medium), seeds SEEDS, and the real-capture composite at medium noise.
# Prints a markdown table and the mean ± std of every column per noise level. SYNTH_ARGS adds
# arguments to the synthetic scenes' `synth` (e.g. "--width 320 --height 240"; default: the
# preset's 160×120).
# Usage: [SYNTH_ARGS=...] scripts/results_training.sh [BUILD_DIR] [WORK_DIR] [SEEDS]
set -euo pipefail
BUILD_DIR=${1:-build}
WORK=${2:-$(mktemp -d)}
SEEDS=${3:-"1 2 3"}
BIN="$BUILD_DIR/clients/cli/instascene"
mkdir -p "$WORK"
rows="$WORK/rows.jsonl"
: > "$rows"
miou() {  # miou SCENE RESULT [--labels-only]
  "$BIN" eval --scene "$1" --result "$2" --json ${3:-} 2>/dev/null | tail -n 1 |
    python3 -c "import json,sys; print('%.4f' % json.load(sys.stdin)['miou'])"
}
scene_row() {  # scene_row GROUP LABEL SCENE
  local s=$3 cells
  "$BIN" decompose --scene "$s" --out "$s/dec" >/dev/null 2>&1
  cells="$(miou "$s" "$s/dec")"
  "$BIN" train --scene "$s" --decomposition "$s/dec" --out "$s/vote" --method vote >/dev/null 2>&1
  cells="$cells $(miou "$s" "$s/vote")"
  for sup in noisy2d 3d 3d+filtered2d full; do
    "$BIN" train --scene "$s" --decomposition "$s/dec" --out "$s/train_$sup" --supervision "$sup" >/dev/null 2>&1
    cells="$cells $(miou "$s" "$s/train_$sup")"
  done
  "$BIN" segment --scene "$s" --features "$s/train_full" --decomposition "$s/dec" --out "$s/full_hdbscan" --labelling hdbscan >/dev/null 2>&1
  cells="$cells $(miou "$s" "$s/train_full" --labels-only) $(miou "$s" "$s/full_hdbscan" --labels-only)"
  python3 -c "import json,sys; print(json.dumps({'group': sys.argv[1], 'scene': sys.argv[2], 'cells': [float(c) for c in sys.argv[3:]]}))" \
    "$1" "$2" $cells >> "$rows"
}
for noise in low medium high sam-medium; do
  for seed in $SEEDS; do
    "$BIN" synth --out "$WORK/s_${noise}_$seed" --preset small --seed "$seed" --mask-noise "$noise" ${SYNTH_ARGS:-} >/dev/null 2>&1
    scene_row "$noise" "small, $noise, seed $seed" "$WORK/s_${noise}_$seed"
  done
done
S=${SPLATS:-"$(cd "$(dirname "$0")/../.." && pwd)/shared/data/splats"}
if [ -d "$S" ]; then
  "$BIN" synth --out "$WORK/composite" --from-splats "$S/statue_massa.ply,$S/playbot_lod4_3dgs_order.ply,$S/statue_angel.ply" \
    --views 32 --width 320 --height 240 --mask-noise medium >/dev/null 2>&1
  scene_row "real composite, medium" "real composite, medium" "$WORK/composite"
fi
python3 - "$rows" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
head = ["decomposition labels", "vote", "noisy 2D", "3D", "3D + filtered 2D", "full",
        "full, tau labels", "full, HDBSCAN labels"]
print("| scene | " + " | ".join(head) + " |")
print("|---|" + "---|" * len(head))
for r in rows:
    print(f"| {r['scene']} | " + " | ".join(f"{c:.3f}" for c in r["cells"]) + " |")
print()
print("| noise | n | " + " | ".join(head) + " |")
print("|---|---|" + "---|" * len(head))
for g in dict.fromkeys(r["group"] for r in rows):
    sel = [r["cells"] for r in rows if r["group"] == g]
    cols = list(zip(*sel))
    cell = lambda v: f"{statistics.mean(v):.3f} ± {statistics.stdev(v):.3f}" if len(v) > 1 else f"{v[0]:.3f}"
    print(f"| {g} | {len(sel)} | " + " | ".join(cell(c) for c in cols) + " |")
PY
