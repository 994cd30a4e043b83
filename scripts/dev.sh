#!/usr/bin/env bash
# crumple's one entry point for a fresh Debian 12 machine (run as root, apt reachable):
#   bash scripts/dev.sh demo   install what is missing, build Release (the CLI and the Python module),
#                              run `crumple simulate` on the thesis' hanging-cloth scene, print a
#                              summary table and the PYTHONPATH line for `import crumple`
#   bash scripts/dev.sh test   install what is missing, build Release and the asan preset, run
#                              every test of both, then the Python tests, then each libFuzzer
#                              target for 15 s (docs/fuzzing.md)
#   bash scripts/dev.sh deps   only install the Debian packages
set -euo pipefail
cd "$(dirname "$0")/.."

JOBS=${JOBS:-$(nproc)}
PACKAGES=(g++ cmake make libeigen3-dev libtbb-dev libpugixml-dev libcli11-dev libgtest-dev
          libgmock-dev libbenchmark-dev libglfw3-dev libimgui-dev libstb-dev xvfb xauth
          libgl1-mesa-dri libgl-dev libgmp-dev pybind11-dev python3-dev python3-numpy
          python3-pytest python3-matplotlib clang libclang-rt-14-dev)

install_deps() {
  local missing=()
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if ((${#missing[@]})); then
    echo "== installing: ${missing[*]}"
    local sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
  fi
}

build() {  # build PRESET
  cmake --preset "$1" >/dev/null
  cmake --build --preset "$1" -j "$JOBS"
}

# Elapsed seconds per phase, printed at the end, also when a phase fails (set -e stops the
# script there), so that a CI log shows where the time went.
PHASES=()
CURRENT=""
phase() {  # phase NAME COMMAND...
  CURRENT=$1
  local start=$SECONDS
  shift
  "$@"
  PHASES+=("$(printf '%-16s %5d s' "$CURRENT" $((SECONDS - start)))")
  CURRENT=""
}
print_phases() {
  [ -n "$CURRENT" ] && PHASES+=("$(printf '%-16s FAILED' "$CURRENT")")
  echo "== time per phase"
  printf '  %s\n' "${PHASES[@]}"
  printf '  %-16s %5d s\n' total "$SECONDS"
}

case "${1:-}" in
  deps)
    install_deps
    ;;
  demo)
    install_deps
    # Only what the demo runs: the command-line tool, and the Python module `crumple` (a few
    # binding files over the same library; no tests, no benchmarks).
    cmake --preset release >/dev/null
    PYTHON_TARGET=""
    grep -q '^CRUMPLE_BUILD_PYTHON:BOOL=ON' build/release/CMakeCache.txt && PYTHON_TARGET=crumple_python
    cmake --build --preset release -j "$JOBS" --target crumple_cli $PYTHON_TARGET
    # The thesis scene: 10x10 cloth hanging from a corner, 600 frames; prints a summary table
    # (collision share reached, ms per frame by part); frames, stats.csv and state in demo-out/
    # (--force: a previous demo's files there are replaced).
    ./build/release/apps/cli/crumple simulate hanging-cloth --frames 600 --every 10 --out demo-out --force
    cat <<'EOF'

Look at the result (every 10th frame in demo-out/frames, statistics in demo-out/stats.csv):
  ./build/release/apps/cli/crumple render hanging-cloth --frame 160 --out demo-out/frame160.png
  ./build/release/apps/cli/crumple render demo-out/frames --video demo-out/video --force
(the second writes one PNG per saved frame, and demo-out/video/video.mp4 when ffmpeg is installed)
EOF
    if [ -n "$PYTHON_TARGET" ]; then
      cat <<EOF
Python (module built in build/release/python, nothing installed; README.md "Python"):
  PYTHONPATH=$PWD/build/release/python /usr/bin/python3 -c "import crumple; print(crumple.Simulation('hanging-cloth').run(200)['ee'][::20])"
EOF
    else
      echo "Python: module not built (CRUMPLE_BUILD_PYTHON is off: pybind11-dev or python3-dev missing)"
    fi
    ;;
  test)
    trap print_phases EXIT
    phase "install deps" install_deps
    phase "build release" build release
    phase "build asan" build asan
    echo "== Release tests"
    phase "ctest release" ctest --preset release -j "$JOBS" --timeout 900 --output-on-failure
    echo "== AddressSanitizer + UBSan tests"
    phase "ctest asan" ctest --preset asan -j "$JOBS" --timeout 1500 --output-on-failure
    echo "== Python tests (module in build/release/python, Debian's /usr/bin/python3)"
    [ -d build/release/python/crumple ] || { echo "no Python module: reconfigure build/release with -DCRUMPLE_BUILD_PYTHON=ON" >&2; exit 1; }
    PYTHONPATH="$PWD/build/release/python" PYTHONDONTWRITEBYTECODE=1 \
      phase pytest /usr/bin/python3 -m pytest tests/python -q -p no:cacheprovider
    echo "== libFuzzer targets, 15 s each over a copy of the seed corpus (docs/fuzzing.md)"
    phase "build fuzz" build fuzz
    phase "fuzz 4 x 15 s" bash scripts/fuzz.sh ci 15
    ;;
  *)
    echo "usage: bash scripts/dev.sh demo|test|deps" >&2
    exit 2
    ;;
esac
