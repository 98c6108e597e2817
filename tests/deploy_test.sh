#!/usr/bin/env bash
# Offline validation of deploy/ and docker/ (no cluster, no container engine here): every overlay
# renders with `kubectl kustomize`; yamllint passes; every rendered object validates against the
# Kubernetes and KEDA schemas (npm kubernetes-models, @kubernetes-models/keda; installed from the
# committed lockfile into the build folder); every container's binary exists in the build and in
# docker/Dockerfile, and its ports match its --listen. Usage: deploy_test.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
SRC=$1
BUILD=$2
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
source "$(dirname "$0")/npm_tools.sh"
command -v kubectl >/dev/null || { echo "FAIL: kubectl missing"; exit 1; }
command -v yamllint >/dev/null || { echo "FAIL: yamllint missing (scripts/install-deps.sh installs it)"; exit 1; }
rendered=()
for overlay in "$SRC"/deploy/overlays/*/; do
  name=$(basename "$overlay")
  kubectl kustomize "$overlay" > "$WORK/$name.yaml"
  rendered+=("$WORK/$name.yaml")
done
yamllint -d '{extends: default, rules: {line-length: {max: 120}, document-start: disable, truthy: {check-keys: false}}}' \
  "$SRC/deploy"
V="$BUILD/deploy-validate"
npm_ci_tools "$SRC/tests/deploy" "$V" || { echo "FAIL: npm ci of the schema packages"; exit 1; }
cp "$SRC/tests/deploy/validate.mjs" "$SRC/tests/deploy/consistency.mjs" "$V/"
node "$V/validate.mjs" "${rendered[@]}" | tail -n 1 > "$WORK/schema.txt"
node "$V/consistency.mjs" "$BUILD/bin" "$SRC/docker/Dockerfile" "${rendered[@]}" | tail -n 1 > "$WORK/consistency.txt"
cat "$WORK/schema.txt" "$WORK/consistency.txt"
python3 - "$WORK/schema.txt" "$WORK/consistency.txt" <<'PY'
import re, sys
p = f = 0
for path in sys.argv[1:]:
    m = re.match(r"(\d+) passed, (\d+) failed", open(path).read().strip())
    p += int(m.group(1)); f += int(m.group(2))
print(f"{p} passed, {f} failed")
sys.exit(0 if f == 0 and p > 0 else 1)
PY
