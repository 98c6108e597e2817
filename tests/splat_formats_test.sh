#!/usr/bin/env bash
# Splat files written by a tool nobody here wrote load here as they load there: a random 3DGS PLY
# (SH degree 3, fully opaque and transparent splats among them) converted by @playcanvas/
# splat-transform 2.7.1 (npm, from the committed lockfile into the build folder) to a SuperSplat
# compressed PLY, .spz version 4 (zstd) and version 3 (gzip); each file read by `instascene convert`
# and by splat-transform itself (its own decoding, written as a PLY), attribute by attribute; and
# against the original within the formats' quantisation. A .splat written here is read both ways too.
# The files then go through `instascene info`, `render` and `import`. Prints "N passed, N failed".
# Usage: splat_formats_test.sh INSTASCENE SOURCE_DIR BUILD_DIR
set -uo pipefail
BIN=$1
SRC=$2
BUILD=$3
source "$(dirname "$0")/test_lib.sh"
source "$(dirname "$0")/npm_tools.sh"
T="$BUILD/splat-interop"
npm_ci_tools "$SRC/tests/splat" "$T" || { echo "FAIL: npm ci of splat-transform"; exit 1; }
st() { HOME="$WORK" node "$T/node_modules/@playcanvas/splat-transform/bin/cli.mjs" -w "$@"; }
compare() { python3 "$SRC/tests/splat/compare_ply.py" "$@"; }

check "a random 3DGS splat" python3 "$SRC/tests/splat/random_3dgs.py" "$WORK/in.ply" 3000 7
check "splat-transform: compressed PLY" st "$WORK/in.ply" "$WORK/a.compressed.ply"
check "splat-transform: spz v4" st "$WORK/in.ply" "$WORK/a.spz"
check "splat-transform: spz v3" st --spz-version 3 "$WORK/in.ply" "$WORK/a3.spz"
check "our .splat" "$BIN" convert --in "$WORK/in.ply" --out "$WORK/a.splat"
for f in a.compressed.ply a.spz a3.spz a.splat; do
  check "$f: read here" "$BIN" convert --in "$WORK/$f" --out "$WORK/ours-$f.ply"
  check "$f: read by splat-transform" st "$WORK/$f" "$WORK/theirs-$f.ply"
  # Same decoding: float rounding only (splat-transform decodes in float64 and stores float32).
  check "$f: ours = splat-transform's, attribute by attribute" compare "$WORK/ours-$f.ply" "$WORK/theirs-$f.ply" 2e-4
  cat "$WORK/out.txt"
done
# Against the original, within each format's quantisation (compressed PLY: 11-bit positions over
# a 256-splat chunk's bounds, 8-bit SH; spz: 12-bit fixed point, 8-bit log-scales (1/16), 8-bit
# colour; .splat: 8-bit colour and quaternions).
check "compressed PLY within its quantisation" compare "$WORK/in.ply" "$WORK/ours-a.compressed.ply.ply" 0.1 --match
cat "$WORK/out.txt"
check "spz within its quantisation" compare "$WORK/in.ply" "$WORK/ours-a.spz.ply" 0.1
cat "$WORK/out.txt"
check "spz v3 = spz v4" compare "$WORK/ours-a3.spz.ply" "$WORK/ours-a.spz.ply" 1e-6
check "opaque splats load with opacity 1" python3 -c "
import math, struct, sys
sys.path.insert(0, '$SRC/tests/splat')
from compare_ply import read
theirs = read('$WORK/theirs-a.compressed.ply.ply')['opacity']; ours = read('$WORK/ours-a.compressed.ply.ply')['opacity']
opaque = [o for t, o in zip(theirs, ours) if t == math.inf]
assert opaque, 'splat-transform wrote no +inf logit'
assert all(struct.unpack('f', struct.pack('f', 1 / (1 + math.exp(-o))))[0] == 1 for o in opaque), opaque[:5]
"
check "info on a .spz" "$BIN" info --ply "$WORK/a.spz" --json
check "render a compressed PLY" "$BIN" render --ply "$WORK/a.compressed.ply" --orbit 30,15 --width 64 --height 48 --out "$WORK/r.png"
check_fails "NaN opacity stays an error" "not finite\|NaN\|nan" "$BIN" convert --in "$SRC/tests/splat/nan_opacity.ply" --out "$WORK/nan.ply"
check_fails "garbage is refused with the formats named" "compressed PLY, .splat, .spz" "$BIN" convert --in "$SRC/tests/splat/package.json" --out "$WORK/g.ply"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
