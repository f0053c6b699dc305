// Which cases the sanitized build runs. A diagnosis runs about ten times slower under
// AddressSanitizer + UndefinedBehaviorSanitizer, so that build runs each code path once: a case
// that repeats a path another case of its suite already takes there carries `release_only()`.
// Its figures are asserted by the Release build.
#pragma once

#include <doctest/doctest.h>

namespace valvediag::test {

#ifdef VALVEDIAG_SANITIZED
inline constexpr bool kSanitizedBuild = true;
#else
inline constexpr bool kSanitizedBuild = false;
#endif

// Decorator: TEST_CASE("..." * valvediag::test::release_only()).
inline doctest::skip release_only() {
  return doctest::skip(kSanitizedBuild);
}

// Decorator of the figure grids over many loops or seeds: doctest's test suite "accuracy", which
// ctest runs under the label `accuracy` (scripts/accuracy.sh), never in test.sh nor sanitized.
inline doctest::test_suite accuracy() {
  return doctest::test_suite("accuracy");
}

}  // namespace valvediag::test
