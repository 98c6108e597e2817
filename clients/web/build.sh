#!/usr/bin/env bash
# Bundles the web UI: clients/web copied to BUILD/web-build, its npm packages installed there from
# the committed lockfile (npm ci, only when the lockfile changed), then Vite writes BUILD/web, which
# the gateway serves at "/". Nothing is written into the source tree.
# Usage: build.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
SRC=$1
BUILD=$2
W="$BUILD/web-build"
mkdir -p "$W"
if ! cmp -s "$SRC/package-lock.json" "$W/package-lock.json" || [ ! -d "$W/node_modules" ]; then
  cp "$SRC/package.json" "$SRC/package-lock.json" "$W/"
  (cd "$W" && npm ci --no-audit --no-fund --loglevel=error)
fi
rm -rf "$W/src" "$W/tests"
cp -r "$SRC/src" "$SRC/tests" "$W/"
cp "$SRC/index.html" "$SRC/vite.config.js" "$W/"
(cd "$W" && INSTASCENE_WEB_OUT="$BUILD/web" npx --no-install vite build --logLevel warn)
test -f "$BUILD/web/index.html"
