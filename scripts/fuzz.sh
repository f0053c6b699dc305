#!/usr/bin/env bash
# Builds the libFuzzer targets in build-fuzz (clang, ASan + UBSan) and runs each for a bounded
# time: FUZZ_SECONDS (default 60) per target. Crash inputs are copied to
# test/fuzz/regressions/<corpus>/, where test_io (csv) and test_bus (site_config, dbc, codec)
# replay them; the script then fails.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
seconds=${FUZZ_SECONDS:-60}
build="$root/build-fuzz"

VALVEDIAG_FUZZ_DEPS=1 "$root/scripts/install-deps.sh"

CC=clang CXX=clang++ cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DVALVEDIAG_FUZZ=ON -DVALVEDIAG_TESTS=OFF >/dev/null

# target:corpus pairs; the corpus names a folder under test/fuzz/corpus and test/fuzz/regressions.
targets=(fuzz_csv:csv fuzz_site_config:site_config fuzz_dbc:dbc fuzz_codec:codec)

status=0
for pair in "${targets[@]}"; do
  target=${pair%%:*}
  corpus=${pair##*:}
  cmake --build "$build" --target "$target" -j "$(nproc)"
  # New inputs go to the work corpus in the build dir; the seeds in git stay as written.
  work="$build/corpus/$corpus"
  artifacts="$build/artifacts/$corpus"
  regressions="$root/test/fuzz/regressions/$corpus"
  rm -rf "$artifacts"  # only this run's findings count
  mkdir -p "$work" "$artifacts"
  seeds=("$root/test/fuzz/corpus/$corpus")
  [ -d "$regressions" ] && seeds+=("$regressions")
  echo "== $target: ${seconds} s"
  set +e
  "$build/test/fuzz/$target" "$work" "${seeds[@]}" -max_total_time="$seconds" -max_len=65536 \
    -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$artifacts/" \
    2>"$build/$target.log"
  rc=$?
  set -e
  tail -n 15 "$build/$target.log"
  found=0
  for f in "$artifacts"/crash-* "$artifacts"/leak-* "$artifacts"/timeout-* "$artifacts"/oom-*; do
    [ -e "$f" ] || continue
    mkdir -p "$regressions"
    cp "$f" "$regressions/"
    echo "$target: $(basename "$f") copied to ${regressions#"$root"/}"
    found=1
  done
  if [ $rc -ne 0 ] || [ $found -ne 0 ]; then
    echo "$target FAILED (exit $rc); log: $build/$target.log"
    status=1
  else
    echo "$target: no crash in ${seconds} s"
  fi
done
exit $status
