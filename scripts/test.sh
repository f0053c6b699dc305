#!/usr/bin/env bash
# Installs what is missing, builds, runs the tests through ctest, then again under
# AddressSanitizer + UndefinedBehaviorSanitizer. The figure grids (ctest label `accuracy`) are
# scripts/accuracy.sh's.
set -euo pipefail
cd "$(dirname "$0")/.."
VALVEDIAG_TEST_DEPS=1 scripts/install-deps.sh
jobs=$(nproc)
# Each phase's wall time, for keeping CI within its limit.
phase() { echo "== test.sh: $1 done at ${SECONDS} s"; }
phase "dependencies"
# Ninja for a new build tree (an existing one keeps its generator): it compiles a target's files
# while the libraries it links are still building, where Make waits, and so keeps both cores busy
# (the sanitizer build: 198 % of a core against 163 %, 637 s against 836 s on this machine).
export CMAKE_GENERATOR="${CMAKE_GENERATOR:-Ninja}"
# Unity builds: a target's files parse Eigen, nlohmann/json, CLI11 and doctest once and emit their
# inline code once (docs/performance.md has the figures). A plain `cmake -S . -B build` stays
# file by file, for quick rebuilds while editing.
unity=-DCMAKE_UNITY_BUILD=ON
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release "$unity"
cmake --build build -j"$jobs"
phase "Release build"
ctest --test-dir build --output-on-failure -j"$jobs" -LE accuracy
phase "Release tests"
# The benchmarks are built (with -Werror) and run by the Release tree and their scripts.
cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DVALVEDIAG_SANITIZE=ON \
  -DVALVEDIAG_BENCH=OFF "$unity"
cmake --build build-asan -j"$jobs"
phase "sanitizer build"
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ctest --test-dir build-asan --output-on-failure -j"$jobs" -LE accuracy
phase "sanitizer tests"
