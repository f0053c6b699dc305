#!/usr/bin/env bash
# Speed of the identification: full default grid at several N, beside a straightforward baseline
# (dense relay matrix, cold NNLS per solve) built from the same code, in one run. Then the
# recorder's load benchmark: 50 loops x OP/PV/SP at 10 Hz from the simulated PLC over loopback
# for LOAD_SECONDS (default 60) s, with the cores idle and then all kept busy, and the SQLite
# insert rate. Then the ARX structure search that
# every trial fit repeats, beside a plain scan of every structure (the same answer, checked;
# SEARCH_REPS, default 5, runs). Then the sweep's throughput: six simulated loops swept on one
# core (the baseline), with --jobs 1 (each loop's fits threaded over the cores) and with one loop
# per core; SWEEP_REPS (default 3) runs each, medians and speed-ups. Then the stiction
# quantification at 3000-48000 samples beside computing every valve path (QUANT_REPS, default 3,
# runs). Last, the speed targets of issue 33: fit at 25,000 samples, diagnose --auto at 4,000 and a
# sweep over the 41 shared plant files, each beside the same run on one core (TARGET_REPS,
# default 3, runs). Arguments go to the first part.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
export CMAKE_GENERATOR="${CMAKE_GENERATOR:-Ninja}"  # as test.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target valvediag_bench valvediag_load_bench \
  valvediag_structure_bench valvediag_quantification_bench valvediag_prediction_bench \
  valvediag >/dev/null
build/bench/valvediag_bench "$@"
echo
echo "== recorder load"
build/bench/valvediag_load_bench "${LOAD_SECONDS:-60}"

echo
echo "== structure search"
build/bench/valvediag_structure_bench "${SEARCH_REPS:-5}"

echo
echo "== one-step prediction error (the prediction refit's evaluations)"
build/bench/valvediag_prediction_bench "${SEARCH_REPS:-5}"

echo
cores=$(nproc)
echo "== sweep: 6 simulated loops of 2000 samples; one core (taskset) beside --jobs 1 and --jobs $cores"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
v=build/src/cli/valvediag
for s in paper-ex1 kano deadband linear-clean characteristic second-order; do
  $v simulate --scenario "$s" --seed 1 --samples 2000 --out "$work/$s.csv" >/dev/null
done
# Wall seconds of one command; arguments: the command.
seconds() {
  local t0 t1
  t0=$(date +%s.%N)
  "$@" >/dev/null
  t1=$(date +%s.%N)
  awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f\n", b - a }'
}
# One sweep over the files; arguments: a command prefix (may be empty), --jobs.
sweep_seconds() {
  # shellcheck disable=SC2086  # the prefix is words or nothing
  seconds $1 $v sweep "$work"/*.csv --jobs "$2" --json "$work/out.json"
}
median() { sort -n | awk '{ v[NR] = $1 } END { print v[int((NR + 1) / 2)] }'; }
reps=${SWEEP_REPS:-3}
base=$(for _ in $(seq "$reps"); do sweep_seconds "taskset -c 0" 1; done | median)
one=$(for _ in $(seq "$reps"); do sweep_seconds "" 1; done | median)
all=$(for _ in $(seq "$reps"); do sweep_seconds "" "$cores"; done | median)
awk -v base="$base" -v one="$one" -v all="$all" -v c="$cores" -v r="$reps" 'BEGIN {
  printf "  one core (baseline):  %6.2f s, %5.1f loops/min\n", base, 6 * 60 / base
  printf "  --jobs 1, %d threads:  %6.2f s, %5.1f loops/min, %.2f x the baseline\n", c, one, 6 * 60 / one, base / one
  printf "  --jobs %d, 1 thread:   %6.2f s, %5.1f loops/min, %.2f x the baseline\n", c, all, 6 * 60 / all, base / all
  printf "  (medians of %d runs)\n", r
}'

echo
echo "== stiction quantification"
build/bench/valvediag_quantification_bench "${QUANT_REPS:-3}"

echo
echo "== speed targets (issue 33): medians of ${TARGET_REPS:-3} runs, beside one core (taskset) as the baseline"
# One target: its name, the goal in s, then the command.
target() {
  local name=$1 goal=$2 reps=${TARGET_REPS:-3} all base
  shift 2
  all=$(for _ in $(seq "$reps"); do seconds "$@"; done | median)
  base=$(for _ in $(seq "$reps"); do seconds taskset -c 0 "$@"; done | median)
  awk -v n="$name" -v g="$goal" -v a="$all" -v b="$base" -v c="$cores" 'BEGIN {
    printf "  %-34s %6.2f s on %d cores (goal < %s s, %s), %6.2f s on one core\n", n, a, c, g,
      a < g ? "met" : "NOT met", b
  }'
}
$v simulate --scenario paper-ex1 --seed 1 --samples 25000 --out "$work/fit25k.csv" >/dev/null
$v simulate --scenario paper-ex1 --seed 1 --samples 4000 --out "$work/auto4k.csv" >/dev/null
target "fit, 25,000 samples" 3 $v fit "$work/fit25k.csv" --no-history
target "diagnose --auto, 4,000 samples" 4 $v diagnose "$work/auto4k.csv" --auto --no-history
shared=${VALVEDIAG_SHARED_DIR:-../shared}
plant="$shared/data/plant-loops"
if [ -d "$plant" ]; then
  target "sweep, $(ls "$plant"/stiction/* "$plant"/no-stiction/* | wc -l) plant files, --jobs $cores" 25 \
    $v sweep "$plant"/stiction/* "$plant"/no-stiction/* --delimiter tab --skip-lines 2 \
    --skip-after-header 2 --time-format "%Y-%m-%d %H:%M:%S" --t 1 --op "*.MV" --pv "*.PV" \
    --sp "*.SV" --jobs "$cores" --json "$work/plant.json"
else
  echo "  no $plant: the sweep target is skipped"
fi
