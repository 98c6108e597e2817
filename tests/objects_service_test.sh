#!/usr/bin/env bash
# The Objects service and the C++ client end to end, as a robot fleet uses them: `instascene serve`
# runs a tiny metric scene through decompose, train, segment, complete and export; then
#   - `instascene objects` lists every exported object in metres;
#   - `instascene object --id --out` downloads every artefact, and each file's SHA-256 equals the
#     digest the service announced;
#   - by point, click and ray the service names the same object as the offline query index over
#     the fetched segmentation (`instascene query`), most of them on objects;
#   - unknown scene, unknown id, a point far from every object, a click on background: NOT_FOUND;
#   - a scene run without export answers from its completed objects (source "complete");
#   - the installed client package (cmake --install, component client) builds the example in a
#     separate CMake project, which finds an object by a 3D point and downloads it.
# Usage: objects_service_test.sh INSTASCENE SOURCE_DIR BUILD_DIR
set -uo pipefail
BIN=$1
SRC=$2
BUILD=$3
source "$(dirname "$0")/test_lib.sh"
SMALL='{"train":{"iterations":60,"samples":512,"pixel_pool":1024}}'

check "synth scene a" "$BIN" synth --out "$WORK/a" --preset tiny --seed 1
check "synth scene b" "$BIN" synth --out "$WORK/b" --preset tiny --seed 2
start serve "$WORK/ready" "$BIN" serve --data "$WORK/data" --listen 127.0.0.1:0 --ready-file "$WORK/ready"
ADDR=$(cat "$WORK/ready")
export INSTASCENE_TOKEN_FILE="$WORK/data/auth/admin.token"  # written by serve on first start
check "submit a with export" "$BIN" submit --scene "$WORK/a" --server "$ADDR" --params "$SMALL" \
  --stages decompose,train,segment,complete,export
check "submit b without export" "$BIN" submit --scene "$WORK/b" --server "$ADDR" --params "$SMALL" \
  --stages decompose,train,segment,complete
check "watch a" "$BIN" watch --scene a --server "$ADDR"
check "watch b" "$BIN" watch --scene b --server "$ADDR"

check "list a's objects" "$BIN" objects --scene a --server "$ADDR" --json
cp "$WORK/out.txt" "$WORK/objects.json"
N=$(json_get "$WORK/objects.json" "len(d['objects'])")
check "several objects, all exported, in metres" test "$(json_get "$WORK/objects.json" \
  "len(d['objects']) >= 2 and all(o['source'] == 'export' and o['units'] == 'metres' for o in d['objects'])")" = True
ID=$(json_get "$WORK/objects.json" "d['objects'][0]['id']")
check "object by id, downloaded" "$BIN" object --scene a --server "$ADDR" --id "$ID" --out "$WORK/obj" --json
cp "$WORK/out.txt" "$WORK/object.json"
check "every artefact downloaded, its SHA-256 the announced digest" python3 - "$WORK/object.json" "$WORK/obj" <<'PY'
import hashlib, json, os, sys
d = json.loads(open(sys.argv[1]).read().strip().splitlines()[-1])
names = {a['path'] for a in d['artefacts']}
assert {'visual.glb', 'object.urdf', 'object.xml', 'points.ply', 'manifest.json', 'collision/hull.stl'} <= names, names
for a in d['artefacts']:
    data = open(os.path.join(sys.argv[2], a['path']), 'rb').read()
    assert hashlib.sha256(data).hexdigest() == a['sha256'] and len(data) == a['bytes'], a['path']
PY

# The service against the offline query index over the fetched segmentation.
check "fetch a" "$BIN" fetch --scene a --server "$ADDR" --out "$WORK/fetched"
same() {  # same NAME SERVICE_ARGS -- QUERY_ARGS: both name the same object (or both nothing)
  local name=$1; shift
  local service=() query=()
  while [ "$1" != "--" ]; do service+=("$1"); shift; done; shift
  query=("$@")
  local expected got
  expected=$("$BIN" query --scene "$WORK/a" --result "$WORK/fetched/segment" "${query[@]}" --json 2>/dev/null | tail -n 1 |
    python3 -c "import json,sys; print(json.load(sys.stdin)['instance'])")
  got=$("$BIN" object --scene a --server "$ADDR" "${service[@]}" --json 2>/dev/null | tail -n 1 |
    python3 -c "import json,sys; print(json.load(sys.stdin)['id'])" 2>/dev/null || echo 0)
  check "$name: service $got == offline $expected" test "$got" = "$expected" -a "$expected" != ""
  [ "$expected" != "0" ] && found=$((found + 1))
  return 0
}
found=0
POINTS=$(json_get "$WORK/objects.json" "' '.join('%f,%f,%f' % tuple(o['world_from_object']['translation']) for o in d['objects'])")
for p in $POINTS; do
  same "point $p" --point "$p" --max-distance 0.1 -- --point "$p" --max-distance 0.1
done
# Clicks where each object's centre projects in views 3 and 7 (and a corner: background).
CLICKS=$(python3 -c "
import json
views = json.load(open('$WORK/a/scene.json'))['views']
objs = json.loads(open('$WORK/objects.json').read().strip().splitlines()[-1])['objects']
for v in (3, 7):
    cam = views[v]; m = cam['camera_from_world']
    for o in objs:
        p = o['world_from_object']['translation']
        c = [sum(m[i][k] * p[k] for k in range(3)) + m[i][3] for i in range(3)]
        x, y = cam['fx'] * c[0] / c[2] + cam['cx'], cam['fy'] * c[1] / c[2] + cam['cy']
        if c[2] > 0 and 0 <= x < cam['width'] and 0 <= y < cam['height']:
            print('%d:%d,%d' % (v, x, y))
print('3:0,0')")
for click in $CLICKS; do
  same "click view ${click%%:*} at ${click#*:}" --view "${click%%:*}" --pixel "${click#*:}" -- --view "${click%%:*}" --pixel "${click#*:}"
done
for v in 1 5 9; do  # rays from cameras along their optical axes (OpenCV convention: +z forward)
  RAY=$(python3 -c "
import json
m = json.load(open('$WORK/a/scene.json'))['views'][$v]['camera_from_world']
r = [row[:3] for row in m]; t = [row[3] for row in m]
c = [-sum(r[k][i] * t[k] for k in range(3)) for i in range(3)]
print(','.join('%f' % x for x in c + [r[2][0], r[2][1], r[2][2]]))")
  same "ray from camera $v" --ray "$RAY" -- --ray "$RAY"
done
echo "objects found by $found point, click and ray queries"
check "most points, clicks and rays hit an object (the comparisons are not all background)" test "$found" -ge 8
check_fails "an unknown scene" "NOT_FOUND" "$BIN" object --scene nope --server "$ADDR" --id 1
check_fails "an unknown object" "NOT_FOUND: scene 'a' has no object 999" "$BIN" object --scene a --server "$ADDR" --id 999
check_fails "a point far from every object" "NOT_FOUND.*no object within" "$BIN" object --scene a --server "$ADDR" --point 9,9,9
check_fails "a click on background" "NOT_FOUND.*background" "$BIN" object --scene a --server "$ADDR" --view 0 --pixel 0,0
check_fails "a ray into the sky" "NOT_FOUND.*meets no object" "$BIN" object --scene a --server "$ADDR" --ray 0,0,5,0,0,1
check_fails "two selectors" "exactly one of" "$BIN" object --scene a --server "$ADDR" --id 1 --point 0,0,0

check "b's objects come from its completions" "$BIN" objects --scene b --server "$ADDR" --json
check "source complete, in metres" test "$(json_get "$WORK/out.txt" \
  "len(d['objects']) >= 2 and all(o['source'] == 'complete' and o['units'] == 'metres' for o in d['objects'])")" = True

# The installed client package, consumed by a separate CMake project.
check "install the client component" cmake --install "$BUILD" --component client --prefix "$WORK/prefix"
check "the installed headers and the package" test -f "$WORK/prefix/include/instascene/client/client.h" \
  -a -f "$WORK/prefix/lib/cmake/InstaSceneClient/InstaSceneClientConfig.cmake"
check "configure the example against the installed package" cmake -S "$SRC/clients/cpp/examples" \
  -B "$WORK/example" -G Ninja -DCMAKE_PREFIX_PATH="$WORK/prefix" -DCMAKE_BUILD_TYPE=Release
check "build the example" cmake --build "$WORK/example"
P=$(json_get "$WORK/objects.json" "'%f %f %f' % tuple(d['objects'][0]['world_from_object']['translation'])")
# shellcheck disable=SC2086
check "the example finds an object by a point and downloads it" "$WORK/example/object_at_point" "$ADDR" a $P "$WORK/robot"
check "it printed the pose, size and artefacts" grep -q "downloaded .* files" "$WORK/out.txt"
check "the robot has the URDF" test -s "$WORK/robot/object.urdf"

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
