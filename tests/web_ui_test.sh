#!/usr/bin/env bash
# The web UI end to end in Debian's Chromium (clients/web/tests/ui_test.mjs, playwright-core from
# the UI's committed lockfile, installed into BUILD/web-build by the build): `instascene serve`
# with the gateway serving the bundle; a tiny synthetic scene uploaded as a folder through the page,
# run through decompose, train, segment, complete and export (one chunk cut off and resumed); the
# viewer, a click, a download, the same capture as a zip, and the dashboard. Screenshots in BUILD/web-screenshots/. Usage: web_ui_test.sh INSTASCENE BUILD_DIR
set -uo pipefail
BIN=$1
BUILD=$2
source "$(dirname "$0")/test_lib.sh"
command -v chromium >/dev/null || { echo "FAIL: chromium missing (scripts/install-deps.sh installs it)"; exit 1; }
[ -f "$BUILD/web/index.html" ] || { echo "FAIL: no web UI bundle in $BUILD/web (npm missing at build time?)"; exit 1; }
SHOTS="$BUILD/web-screenshots"
mkdir -p "$SHOTS"

check "synth" "$BIN" synth --out "$WORK/capture" --preset tiny --seed 3
start serve "$WORK/ready" "$BIN" serve --data "$WORK/data" --listen 127.0.0.1:0 --ready-file "$WORK/ready" \
  --gateway 127.0.0.1:0 --web-root "$BUILD/web"
GW=http://$(sed -n 's/^gateway=//p' "$WORK/ready")
check "the gateway serves the UI" curl -sf "$GW/" -o "$WORK/index.html"
check "index.html loads the bundle" grep -q 'assets/index-' "$WORK/index.html"
# The browser keeps its profile and downloads under WORK (TMPDIR), removed at exit.
check "the capture as a zip (one folder inside)" python3 -c "
import os, zipfile
with zipfile.ZipFile('$WORK/capture.zip', 'w') as z:
    for d, _, names in os.walk('$WORK/capture'):
        for n in names:
            p = os.path.join(d, n)
            z.write(p, os.path.join('capture', os.path.relpath(p, '$WORK/capture')))
"
HOME="$WORK" TMPDIR="$WORK" node "$BUILD/web-build/tests/ui_test.mjs" "$GW" "$(cat "$WORK/data/auth/admin.token")" \
  "$WORK/capture" "$WORK/capture.zip" tiny-capture "$SHOTS" >"$WORK/ui.txt" 2>&1
cat "$WORK/ui.txt"
ui=$(tail -n 1 "$WORK/ui.txt")
if [[ $ui =~ ^([0-9]+)\ passed,\ ([0-9]+)\ failed$ ]]; then
  passed=$((passed + BASH_REMATCH[1])); failed=$((failed + BASH_REMATCH[2]))
else
  failed=$((failed + 1)); echo "FAIL: the browser test did not finish"; tail -n 30 "$WORK/serve.log"
fi
echo "$passed passed, $failed failed"
[ "$failed" = 0 ]
