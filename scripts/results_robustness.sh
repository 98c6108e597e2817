#!/usr/bin/env bash
# Decomposition robustness on scenes nobody tuned on (docs/RESULTS.md, "Robustness"): for each
# scene, the offline pipeline up to the final labels (`instascene run --stages
# decompose,train,segment`, today's defaults), scored by the click protocol on labels (`eval
# --labels-only`). Every synthetic scene is generated twice: with the coarse table of the scenes
# before 2026-12-03 (`coarse`: `synth --table-detail 1`, whose discs painted over low objects) and
# with today's generator (`refined`). Scenes: the `small` preset at 320x240 (32 views) and 640x480
# (48 views) under both segmenter-noise families, and real-capture composites with the two statues
# pressed together (no table: generated once, `refined` only). Prints a markdown table and
# mean ± std per group and configuration.
set -euo pipefail
BUILD_DIR=${1:-build}
WORK=${2:-$(mktemp -d)}
SEEDS=${3:-"31 32 33 34"}
COMPOSITE_SEEDS=${4:-"5 8 21"}
HIRES_SEEDS=${5:-"41 42"}
SPLATS=${SPLATS:-"$(cd "$(dirname "$0")/../.." && pwd)/shared/data/splats"}
BIN="$BUILD_DIR/clients/cli/instascene"
mkdir -p "$WORK"
rows="$WORK/rows.jsonl"
: > "$rows"
declare -A DETAIL=([coarse]=1 [refined]=3)
score() {  # score GROUP LABEL CONFIG DIR: run the pipeline on DIR and append a row
  local out="$4/run" t0 t1
  rm -rf "$out"
  t0=$(date +%s.%N)
  "$BIN" run --scene "$4" --out "$out" --stages decompose,train,segment >/dev/null 2>&1
  t1=$(date +%s.%N)
  "$BIN" eval --scene "$4" --result "$out/segmentation" --json --labels-only 2>/dev/null |
    tail -n 1 > "$out/eval.json"
  python3 - "$1" "$2" "$3" "$out/eval.json" "$(python3 -c "print($t1-$t0)")" >> "$rows" <<'PY'
import json, sys
group, label, config, path, seconds = sys.argv[1:6]
ev = json.load(open(path))
low = [f"{o['name']} {o['miou']:.2f} ({o['views']} views)" for o in ev["objects"] if o["miou"] < 0.6]
objects = [{"name": o["name"], "miou": o["miou"], "views": o["views"]} for o in ev["objects"]]
print(json.dumps({"group": group, "scene": label, "config": config, "miou": ev["miou"],
                  "ari": ev["ari"], "precision": ev["precision_3d"], "recall": ev["recall_3d"],
                  "seconds": float(seconds), "low": low, "objects": objects}))
PY
}
synth_scene() {  # synth_scene GROUP LABEL DIR SYNTH_ARGS...: both table variants, scored
  local group=$1 label=$2 dir=$3 config
  shift 3
  for config in coarse refined; do
    "$BIN" synth --out "${dir}_$config" --table-detail "${DETAIL[$config]}" "$@" >/dev/null 2>&1
    score "$group" "$label" "$config" "${dir}_$config"
  done
}
for noise in medium sam-medium; do
  for seed in $SEEDS; do
    synth_scene "320x240, $noise" "small 320x240, $noise, seed $seed" "$WORK/small320_${noise}_$seed" \
      --preset small --seed "$seed" --mask-noise "$noise" --width 320 --height 240 --views 32
  done
  for seed in $HIRES_SEEDS; do
    synth_scene "640x480, $noise" "small 640x480, $noise, seed $seed" "$WORK/small640_${noise}_$seed" \
      --preset small --seed "$seed" --mask-noise "$noise" --width 640 --height 480 --views 48
  done
done
for seed in $COMPOSITE_SEEDS; do
  d="$WORK/touching_$seed"
  "$BIN" synth --out "$d" --seed "$seed" --mask-noise medium --width 320 --height 240 --views 32 \
    --gap -0.15 --from-splats \
    "$SPLATS/statue_massa.ply,$SPLATS/statue_angel.ply,$SPLATS/playbot_lod4_3dgs_order.ply" \
    >/dev/null 2>&1
  score "touching statues 320x240, medium" "touching statues, seed $seed" refined "$d"
done
python3 - "$rows" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print("| scene | table | click mIoU (labels) | ARI | 3D precision@0.5 | 3D recall@0.5 | run s | objects < 0.6 |")
print("|---|---|---|---|---|---|---|---|")
for r in rows:
    print(f"| {r['scene']} | {r['config']} | {r['miou']:.3f} | {r['ari']:.3f} | {r['precision']:.2f} | "
          f"{r['recall']:.2f} | {r['seconds']:.0f} | {', '.join(r['low']) or '-'} |")
print()
print("| group | table | n | click mIoU (labels) | ARI | 3D precision@0.5 | 3D recall@0.5 | "
      "thin/concave objects (torus, bowl, cup) | objects seen in ≥ 6 views below 0.6 |")
print("|---|---|---|---|---|---|---|---|---|")
groups = list(dict.fromkeys(r["group"] for r in rows))
def thin(sel):
    v = [o["miou"] for r in sel for o in r["objects"]
         if o["name"].split("_")[0] in ("torus", "bowl", "cup")]
    return f"{statistics.mean(v):.3f} (n = {len(v)})" if v else "-"
def failed(sel):
    bad = sum(1 for r in sel for o in r["objects"] if o["views"] >= 6 and o["miou"] < 0.6)
    return f"{bad} of {sum(1 for r in sel for o in r['objects'] if o['views'] >= 6)}"
def ms(v):
    return f"{statistics.mean(v):.3f} ± {statistics.stdev(v) if len(v) > 1 else 0:.3f}"
for g in groups:
    for config in ("coarse", "refined"):
        sel = [r for r in rows if r["group"] == g and r["config"] == config]
        if sel:
            print(f"| {g} | {config} | {len(sel)} | {ms([r['miou'] for r in sel])} | "
                  f"{ms([r['ari'] for r in sel])} | {ms([r['precision'] for r in sel])} | "
                  f"{ms([r['recall'] for r in sel])} | {thin(sel)} | {failed(sel)} |")
PY
