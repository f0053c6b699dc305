#!/usr/bin/env bash
# Installs the Debian packages valvediag builds and tests against. Only what is missing.
set -euo pipefail
pkgs=(cmake g++ make ninja-build libeigen3-dev libnlopt-cxx-dev doctest-dev libcli11-dev nlohmann-json3-dev
      libtomlplusplus-dev libmodbus-dev libsqlite3-dev libmatio-dev gnuplot-nox libpng-dev
      libcpp-httplib-dev libjs-dygraphs)
# The browser the tests screenshot the pages in (test/report/test_browser.cpp) and drive the
# workbench in over WebDriver (chromium-driver, test/serve/test_workbench_browser.cpp): test.sh's
# only, not the demo's.
[ "${VALVEDIAG_TEST_DEPS:-0}" = 1 ] && pkgs+=(chromium chromium-driver fonts-dejavu-core)
[ "${VALVEDIAG_FUZZ_DEPS:-0}" = 1 ] && pkgs+=(clang libclang-rt-dev)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
