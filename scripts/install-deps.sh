#!/usr/bin/env bash
# Installs every Debian package the InstaScene backend needs. Idempotent: packages that are
# already installed are skipped, and nothing is done (no apt-get update) when all are present.
# Usage: scripts/install-deps.sh [--check]   (--check: exit 1 if something is missing, install nothing)
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config git
  clang-format clang-tidy
  clang libclang-rt-14-dev valgrind
  libabsl-dev
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  libeigen3-dev
  libopencv-dev
  libembree-dev libopen3d-dev
  libopenimageio-dev openimageio-tools
  libdraco-dev
  libtbb-dev
  libsqlite3-dev
  nlohmann-json3-dev
  libspdlog-dev libfmt-dev
  libcli11-dev
  libgtest-dev libgmock-dev
  libbenchmark-dev
  libssl-dev libcurl4-openssl-dev openssl
  libnanoflann-dev
  libcpp-httplib-dev libpugixml-dev
  prometheus-cpp-dev prometheus
  libqhull-dev liburdfdom-tools libmujoco-dev
  libpqxx-dev postgresql-15
  yamllint nodejs chromium
  zlib1g-dev libzstd-dev libpng-dev
  python3-onnx
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

# The S3 tests run moto's server from the machine image's Python (PyPI is not reachable here).
if ! python3 -c "import moto.server, boto3" 2>/dev/null; then
  echo "install-deps: warning: python3 lacks moto/boto3: the S3 store tests will fail (docs/DEPLOY.md)"
fi

if [ "${#missing[@]}" -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi
if [ "${1:-}" = "--check" ]; then
  echo "install-deps: missing: ${missing[*]}"
  exit 1
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "install-deps: done"
