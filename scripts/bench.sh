#!/usr/bin/env bash
# Speed of the identification: full default grid at several N, beside a straightforward baseline
# (dense relay matrix, cold NNLS per solve) built from the same code, in one run. Then the
# recorder's load benchmark: 50 loops x OP/PV/SP at 10 Hz from the simulated PLC over loopback
# for LOAD_SECONDS (default 60) s, and the SQLite insert rate. Arguments go to the first part.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target valvediag_bench valvediag_load_bench >/dev/null
build/bench/valvediag_bench "$@"
echo
echo "== recorder load"
build/bench/valvediag_load_bench "${LOAD_SECONDS:-60}"
