# tests/npm_tools.sh: installing the npm tools a test runs (sourced).
# npm_ci_tools SRC_DIR DEST: installs SRC_DIR's package.json + committed lockfile into DEST (npm ci),
# only when the lockfile changed or DEST has no node_modules yet.
npm_ci_tools() {
  if ! cmp -s "$1/package-lock.json" "$2/package-lock.json" || [ ! -d "$2/node_modules" ]; then
    mkdir -p "$2"
    cp "$1/package.json" "$1/package-lock.json" "$2/"
    (cd "$2" && npm ci --no-audit --no-fund --loglevel=error >/dev/null 2>&1)
  fi
}
