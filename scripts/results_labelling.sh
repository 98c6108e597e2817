#!/usr/bin/env bash
# The final labelling compared (docs/RESULTS.md, "Final labelling"): for each scene and seed, one
# offline run (decompose + train + segment with the tau rule), then the same trained features
# labelled by HDBSCAN; both scored with the click protocol on labels (`eval --labels-only`), with
# 3D instance precision / recall and ARI. Prints a markdown table and mean ± std per labelling.
# Usage: [NOISE="medium sam-medium ..."] scripts/results_labelling.sh [BUILD_DIR] [WORK_DIR] [SEEDS]
set -euo pipefail
BUILD_DIR=${1:-build}
WORK=${2:-$(mktemp -d)}
mkdir -p "$WORK"
SEEDS=${3:-"1 2 3 4"}
BIN="$BUILD_DIR/clients/cli/instascene"
rows="$WORK/rows.jsonl"
: > "$rows"
score() {  # score LABEL SCENE RESULT LABELLING SECONDS
  "$BIN" eval --scene "$2" --result "$3" --json --labels-only 2>/dev/null | tail -n 1 > "$3.eval.json"
  python3 - "$1" "$3.eval.json" "$4" "$5" >> "$rows" <<'PY'
import json, sys
label, path, labelling, seconds = sys.argv[1:5]
ev = json.load(open(path))
print(json.dumps({"scene": label, "labelling": labelling, "miou": ev["miou"], "ari": ev["ari"],
                  "precision": ev["precision_3d"], "recall": ev["recall_3d"],
                  "objects": len(ev["objects"]), "seconds": float(seconds)}))
PY
}
scene() {  # scene LABEL DIR
  local t0 t1 t2
  t0=$(date +%s.%N)
  "$BIN" run --scene "$2" --out "$2/run" >/dev/null 2>&1
  t1=$(date +%s.%N)
  "$BIN" segment --scene "$2" --features "$2/run/training" --out "$2/hdbscan" --labelling hdbscan >/dev/null 2>&1
  t2=$(date +%s.%N)
  score "$1" "$2" "$2/run/segmentation" tau "$(python3 -c "print($t1-$t0)")"
  score "$1" "$2" "$2/hdbscan" hdbscan "$(python3 -c "print($t2-$t1)")"
}
for noise in ${NOISE:-medium high sam-medium sam-high}; do
  for seed in $SEEDS; do
    d="$WORK/small_${noise}_$seed"
    "$BIN" synth --out "$d" --preset small --seed "$seed" --mask-noise "$noise" >/dev/null 2>&1
    scene "small, $noise, seed $seed" "$d"
  done
done
python3 - "$rows" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print("| scene | labelling | objects | click mIoU (labels) | ARI | 3D precision@0.5 | 3D recall@0.5 | labelling s |")
print("|---|---|---|---|---|---|---|---|")
for r in rows:
    print(f"| {r['scene']} | {r['labelling']} | {r['objects']} | {r['miou']:.3f} | {r['ari']:.3f} | "
          f"{r['precision']:.2f} | {r['recall']:.2f} | {r['seconds']:.1f} |")
print()
for labelling in ("tau", "hdbscan"):
    sel = [r for r in rows if r["labelling"] == labelling]
    for key in ("miou", "ari", "precision", "recall"):
        v = [r[key] for r in sel]
        print(f"{labelling} {key}: mean {statistics.mean(v):.3f} ± {statistics.stdev(v) if len(v) > 1 else 0:.3f} (n = {len(v)})")
PY
