# Shared by scripts/demo and scripts/test (sourced): installs the Debian
# packages the build needs, then configures and builds into build/.
# Not root: prints the exact apt-get line and stops.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD=${TISSUE_BUILD_DIR:-$ROOT/build}
PACKAGES=(build-essential cmake pkg-config libfmt-dev libeigen3-dev libtbb-dev libembree-dev libtet1.5-dev
          libassimp-dev libcgal-dev libpugixml-dev libcli11-dev libgtest-dev libgmock-dev
          # the viewer (apps/viewer): windowing, GL through GLEW, EGL, Dear ImGui, PNG; Xvfb + Mesa for pictures
          libglfw3-dev libglew-dev libgl-dev libegl-dev libopengl-dev libimgui-dev libstb-dev
          xvfb xauth libgl1-mesa-dri
          # scripts/fuzz: libFuzzer targets built with clang
          clang-15 libfuzzer-15-dev
          # the Python package (python/): pybind11, NumPy, pytest; matplotlib for scripts/plot and the examples;
          # Dask, SciPy and tqdm for tissue sweep / tissue fit (python/tissue/distributed.py, fitting.py)
          pybind11-dev python3-dev python3-numpy python3-pytest python3-matplotlib
          python3-dask python3-distributed python3-scipy python3-tqdm)

install_packages() {
  local missing=()
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  if [ "$(id -u)" -ne 0 ]; then
    echo "tissue: missing Debian packages. Run as root:" >&2
    echo "  apt-get update && apt-get install -y ${missing[*]}" >&2
    exit 1
  fi
  echo "tissue: installing ${missing[*]}"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}"
}

build_tissue() {
  local jobs
  jobs=$(nproc)
  cmake -S "$ROOT" -B "$BUILD" -DCMAKE_BUILD_TYPE=Release ${TISSUE_CMAKE_ARGS:-}
  cmake --build "$BUILD" -j "$jobs"
  register_python
}

# Makes Debian's python3 import the package just built (docs/python.md): a
# tissue-build.pth naming $BUILD/python in /usr/local's site-packages. Root
# only (as the apt-get step); otherwise it says what to export.
register_python() {
  [ -f "$BUILD/python/tissue/__init__.py" ] || return 0
  local site
  site=$(/usr/bin/python3 -c "import site; print(next(p for p in site.getsitepackages() if p.startswith('/usr/local/')))" 2>/dev/null) || site=""
  if [ "$(id -u)" -eq 0 ] && [ -n "$site" ]; then
    mkdir -p "$site" && echo "$BUILD/python" > "$site/tissue-build.pth"
    echo "tissue: python3 imports tissue from $BUILD/python ($site/tissue-build.pth)"
  else
    echo "tissue: for Python, export PYTHONPATH=$BUILD/python"
  fi
}
