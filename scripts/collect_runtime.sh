#!/usr/bin/env bash
# Copies a binary to OUT/usr/local/bin/ and every shared library `ldd` resolves for it to the same
# absolute path under OUT, so that `COPY OUT/ /` on a slim image of the same Debian release runs it.
# Usage: scripts/collect_runtime.sh BINARY OUT
set -euo pipefail
bin=$1
out=$2
mkdir -p "$out/usr/local/bin"
cp "$bin" "$out/usr/local/bin/"
ldd "$bin" | awk '/=> \//{print $3} /^\s*\/lib/{print $1}' | sort -u | while read -r lib; do
  mkdir -p "$out$(dirname "$lib")"
  cp -L "$lib" "$out$lib"
done
