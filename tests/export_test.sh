#!/usr/bin/env bash
# Robot-ready objects end to end, checked by tools nobody here wrote: a tiny synthetic scene (metric:
# meters_per_unit 1) through decompose, train, segment, complete and export; every visual.glb passes
# the Khronos glTF validator (npm gltf-validator, installed from the committed lockfile into the build
# folder), every object.urdf passes urdfdom's check_urdf, every object.xml loads in MuJoCo and,
# dropped onto a floor, comes to rest within a simulated second (objects_drop_check), and the
# catalogue lists every object in metres; from the ground-truth instances of a scene whose
# never-seen surfels are dropped, every exported object's extents are within 5 % of the truth, and
# so are the pipeline's own objects on that scene, end to end.
# Usage: export_test.sh INSTASCENE SOURCE_DIR BUILD_DIR
set -uo pipefail
BIN=$1
SRC=$2
BUILD=$3
source "$(dirname "$0")/test_lib.sh"
source "$(dirname "$0")/npm_tools.sh"
command -v check_urdf >/dev/null || { echo "FAIL: check_urdf missing (scripts/install-deps.sh installs liburdfdom-tools)"; exit 1; }
V="$BUILD/export-validate"
npm_ci_tools "$SRC/tests/objects" "$V" || { echo "FAIL: npm ci of gltf-validator"; exit 1; }
cp "$SRC/tests/objects/validate_glb.mjs" "$V/"

check "synth" "$BIN" synth --out "$WORK/scene" --preset tiny --seed 1
check "run with export" "$BIN" run --scene "$WORK/scene" --out "$WORK/run" --stages decompose,train,segment,complete,export
n=$(ls -d "$WORK"/run/export/*/ 2>/dev/null | wc -l)
check "one export per completed object" test "$n" -ge 2 -a "$n" = "$(ls -d "$WORK"/run/objects/*/ | wc -l)"
check "the catalogue lists them, in metres" python3 -c "
import json, sys
d = json.load(open('$WORK/run/export/objects.json'))
sys.exit(0 if len(d['objects']) == $n and all(o['units'] == 'metres' for o in d['objects']) else 1)"
check "every visual.glb passes the Khronos glTF validator" node "$V/validate_glb.mjs" "$WORK"/run/export/*/visual.glb
check "every object.xml loads in MuJoCo and comes to rest on a floor within a simulated second" \
  "$BUILD/services/objects/objects_drop_check" "$WORK"/run/export/*/object.xml
# Placement and metric scale against the ground truth: each exported mesh, placed by its
# world_from_object, lies on a ground-truth object (mean Chamfer under 2 cm; a wrong pose or scale
# is off by decimetres). The extents are reported, not asserted, on this scene: it keeps the
# surfels no view sees, and the hidden backs of touching bottles go to the neighbour whose seen
# surfels are nearest (docs/OBJECTS.md, "Checked by tools nobody here wrote"); they are asserted
# end to end on the same scene with those surfels dropped, below.
check "eval --export" "$BIN" eval --scene "$WORK/scene" --export "$WORK/run/export" --json
check "every exported object lies on a ground-truth object" python3 -c "
import json, sys
d = json.loads(open('$WORK/out.txt').read().strip().splitlines()[-1])
sys.exit(0 if d['count'] == $n and d['mean']['chamfer_m'] < 0.02 else 1)"
# The offline export command runs the same stage code on the completed objects: the same bytes.
check "export again from the completed objects" "$BIN" export --scene "$WORK/scene" --objects "$WORK/run/objects" --out "$WORK/export"
check "the offline export equals the pipeline's, byte for byte" diff -r "$WORK/run/export" "$WORK/export"
check_fails "export of a folder without completed objects" "no completed object" "$BIN" export --scene "$WORK/scene" --objects "$WORK/scene" --out "$WORK/none"
check "and it wrote nothing" test ! -e "$WORK/none"
# The completion and export stages on their own, asserted: from the ground-truth instances of a
# scene whose never-seen surfels are dropped (what a model trained on the images holds; the
# completion must add the hidden sides), every object's extents are within 5 % of the
# ground-truth object's. What stays outside 5 % in the pipeline's run above is the decomposition's
# (touching objects' surfels given to the neighbour: docs/OBJECTS.md, "Measured").
check "synth with the unseen surfels dropped" "$BIN" synth --out "$WORK/seen" --preset tiny --seed 1 --unseen drop
check "complete the ground-truth instances" "$BIN" complete --scene "$WORK/seen" --result "$WORK/seen/gt" --out "$WORK/seen_objects"
check "export them" "$BIN" export --scene "$WORK/seen" --objects "$WORK/seen_objects" --out "$WORK/seen_export"
check "eval --export of the ground-truth instances" "$BIN" eval --scene "$WORK/seen" --export "$WORK/seen_export" --json
check "from the ground-truth instances every object's extents are within 5 %" python3 -c "
import json, sys
d = json.loads(open('$WORK/out.txt').read().strip().splitlines()[-1])
print([(o['gt_name'], round(o['extent_error'], 3)) for o in d['objects']])
sys.exit(0 if d['count'] == 5 and d['extents_within_5_percent'] == d['count'] and d['mean']['chamfer_m'] < 0.01 else 1)"
# End to end on that scene (what a trained capture holds: no surfel where no view looked), every
# exported object's extents are within 5 % of the ground-truth object's.
check "run with export on the scene without never-seen surfels" "$BIN" run --scene "$WORK/seen" --out "$WORK/seen_run" --stages decompose,train,segment,complete,export
check "eval --export of the pipeline's objects" "$BIN" eval --scene "$WORK/seen" --export "$WORK/seen_run/export" --json
check "end to end every object's extents are within 5 %" python3 -c "
import json, sys
d = json.loads(open('$WORK/out.txt').read().strip().splitlines()[-1])
print([(o['gt_name'], round(o['extent_error'], 3)) for o in d['objects']])
sys.exit(0 if d['count'] == 5 and d['extents_within_5_percent'] == d['count'] and d['mean']['chamfer_m'] < 0.01 else 1)"
for urdf in "$WORK"/run/export/*/object.urdf; do
  check "check_urdf $(basename "$(dirname "$urdf")")" check_urdf "$urdf"
done

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
