#!/usr/bin/env bash
# The Table-2 variants of scripts/results_training.sh scored at several click thresholds: for each
# synthetic scene of a finished WORK_DIR (s_<noise>_<seed>/train_<variant>), `instascene eval
# --threshold T` (click mIoU with features) for T in THRESHOLDS. Prints, per noise level, the mean
# over seeds of each variant at each threshold and of each run's best threshold (docs/RESULTS.md,
# "The click threshold and the ordering").
# Usage: scripts/results_threshold_sweep.sh [BUILD_DIR] WORK_DIR [THRESHOLDS]
set -euo pipefail
BUILD_DIR=${1:-build}
WORK=${2:?usage: scripts/results_threshold_sweep.sh [BUILD_DIR] WORK_DIR [THRESHOLDS]}
THRESHOLDS=${3:-"0.5 0.6 0.65 0.7 0.75 0.8 0.85 0.9 0.95"}
BIN="$BUILD_DIR/clients/cli/instascene"
rows="$WORK/threshold_rows.txt"
: > "$rows"
for s in "$WORK"/s_*; do
  [ -d "$s" ] || continue
  for v in noisy2d 3d 3d+filtered2d full; do
    [ -d "$s/train_$v" ] || continue
    for t in $THRESHOLDS; do
      m=$("$BIN" eval --scene "$s" --result "$s/train_$v" --json --threshold "$t" 2>/dev/null |
        tail -n 1 | python3 -c "import json,sys; print(json.load(sys.stdin)['miou'])")
      echo "$(basename "$s") $v $t $m" >> "$rows"
    done
  done
done
python3 - "$rows" <<'PY'
import collections, statistics, sys
score = collections.defaultdict(dict)  # (scene, variant) -> threshold -> mIoU
for line in open(sys.argv[1]):
    scene, variant, t, m = line.split()
    score[(scene, variant)][t] = float(m)
variants = ["noisy2d", "3d", "3d+filtered2d", "full"]
groups = dict.fromkeys(s.rsplit("_", 1)[0][2:] for s, _ in score)
for g in groups:
    scenes = sorted({s for s, _ in score if s.rsplit("_", 1)[0][2:] == g})
    print(f"\n{g} ({len(scenes)} seeds): " + " / ".join(variants))
    thresholds = list(score[(scenes[0], "3d")])
    for t in thresholds:
        cells = [statistics.mean(score[(s, v)][t] for s in scenes) for v in variants]
        print(f"  threshold {t}: " + " / ".join(f"{c:.3f}" for c in cells))
    best = [statistics.mean(max(score[(s, v)].values()) for s in scenes) for v in variants]
    print("  best per run: " + " / ".join(f"{c:.3f}" for c in best))
PY
