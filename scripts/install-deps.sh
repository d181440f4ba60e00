#!/usr/bin/env bash
# Installs exactly the Debian 12 packages ltmapper needs (see DESIGN.md "Dependencies").
# Idempotent: packages already installed are skipped, and apt-get is not called at all when
# nothing is missing. Works as root without sudo, and through sudo otherwise.
set -euo pipefail

PACKAGES=(
  build-essential cmake pkg-config ccache
  libeigen3-dev          # linear algebra, poses
  libceres-dev           # pose graph back end
  libpcl-dev             # global registration: normals, kd-tree search, RANSAC (tests: PCL's PCD files, FPFH)
  liblz4-dev             # FLANN's headers, compiled in with PCL's templates
  liblzf-dev             # binary_compressed PCDs
  libnanoflann-dev       # kd-tree for hot loops
  libboost-dev           # Boost.Geometry's convex hull (objects' oriented boxes; headers only)
  libtbb-dev             # parallel_for / parallel_reduce
  libembree-dev          # ray casting (simulator)
  libsqlite3-dev         # map store
  libzstd-dev            # blob compression
  libyaml-cpp-dev        # params files
  libcli11-dev           # command line
  libspdlog-dev          # logging
  libpng-dev             # PNG renders
  libgtest-dev libgmock-dev libbenchmark-dev   # tests and benchmarks
  pybind11-dev python3-dev python3-numpy       # Python bindings (python/, `import ltmapper`)
  python3-pytest                               # their tests (ctest python_bindings)
  python3-distributed                          # Dask: the tile jobs on a cluster (python/ltmapper_dask.py, ctest tiles_dask)
  libcpp-httplib-dev nlohmann-json3-dev        # ltmapper view: HTTP server, JSON
  libcmark-gfm-dev libcmark-gfm-extensions-dev # reports: Markdown to HTML (GitHub's tables)
  chromium               # headless browser of the viewer's browser test (tests/browser/)
)
# three.js and playwright-core come from the npm registry (web/package-lock.json): Debian's node
# and npm unless a node with npm is installed already (e.g. NodeSource's, which conflicts with them).
if ! command -v npm >/dev/null 2>&1; then
  PACKAGES+=(nodejs npm)
fi

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

# web/node_modules (three.js for `ltmapper view`, playwright-core for its test): exactly the
# versions of web/package-lock.json; nothing to do when they are there already.
install_web() {
  local web
  web="$(cd "$(dirname "${BASH_SOURCE[0]}")/../web" && pwd)"
  if [ -f "$web/node_modules/three/package.json" ] && [ -f "$web/node_modules/playwright-core/package.json" ] &&
     [ "$web/node_modules/.package-lock.json" -nt "$web/package-lock.json" ]; then
    return 0
  fi
  echo "install-deps: npm ci in $web"
  (cd "$web" && npm ci --no-audit --no-fund)
}

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages already installed"
  install_web
  exit 0
fi

if [ "$(id -u)" -eq 0 ]; then
  SUDO=()
elif command -v sudo >/dev/null 2>&1; then
  SUDO=(sudo)
else
  echo "install-deps: need root or sudo to install: ${missing[*]}" >&2
  exit 1
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${SUDO[@]}" apt-get update -q
"${SUDO[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
install_web
