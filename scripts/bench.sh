#!/usr/bin/env bash
# Speed of the identification: full default grid at several N, beside a straightforward baseline
# (dense relay matrix, cold NNLS per solve) built from the same code, in one run.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target valvediag_bench >/dev/null
exec build/bench/valvediag_bench "$@"
