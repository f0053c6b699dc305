#!/usr/bin/env bash
# Installs what is missing, builds Release and runs the main job on its embedded default:
# the paper's Example 1 simulated, identified and compared with the paper.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
export CMAKE_GENERATOR="${CMAKE_GENERATOR:-Ninja}"  # as test.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target valvediag >/dev/null
exec build/src/cli/valvediag demo "$@"
