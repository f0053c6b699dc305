#!/usr/bin/env bash
# The diagnosis's accuracy on loops it was not tuned to.
#  1. The randomized benchmark (bench/accuracy.cpp, src/sim/random_loop.cpp): loops drawn from
#     wide ranges, each with one effect hidden from the model diagnose starts from (two, or none
#     for the controls). Two disjoint seed ranges side by side: the development seeds, which may
#     be studied, and the test seeds, which are only ever run. A gap between them is over-fitting.
#  2. The plant loops of ../shared/data/plant-loops: the sweep's verdict against the provider's
#     labels, per file and per valve tag (12 of the 18 sticky files are one valve).
#  3. The tests' figure grids (ctest label `accuracy`: plant loops, whole-record thresholds under
#     leave-one-tag-out, the named and seeded effect cases), which test.sh leaves out.
# Arguments go to the benchmark (--dev FIRST:COUNT, --test FIRST:COUNT, --only EFFECT, --jobs N,
# --json FILE: every case's findings with their statistics, to study a ranking offline).
# About 25 minutes on 2 cores, and 10 more for the grids.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
export CMAKE_GENERATOR="${CMAKE_GENERATOR:-Ninja}"  # as test.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" >/dev/null
echo "== randomized benchmark ($(git rev-parse --short HEAD 2>/dev/null || echo unknown), $(date -u +%Y-%m-%d))"
build/bench/valvediag_accuracy "$@"

shared=${VALVEDIAG_SHARED_DIR:-../shared}
plant="$shared/data/plant-loops"
if [ -d "$plant" ]; then
  echo
  echo "== plant loops ($plant)"
  work=$(mktemp -d)
  trap 'rm -rf "$work"' EXIT
  build/src/cli/valvediag sweep "$plant"/stiction/* "$plant"/no-stiction/* --delimiter tab \
    --skip-lines 2 --skip-after-header 2 --time-format "%Y-%m-%d %H:%M:%S" --t 1 --op "*.MV" \
    --pv "*.PV" --sp "*.SV" --jobs "$(nproc)" --json "$work/plant.json" >/dev/null || true
  build/bench/valvediag_accuracy --plant "$work/plant.json"
else
  echo "no $plant: the plant part is skipped"
fi
echo
echo "== the tests' figure grids (ctest -L accuracy)"
ctest --test-dir build --output-on-failure -j"$(nproc)" -L accuracy
