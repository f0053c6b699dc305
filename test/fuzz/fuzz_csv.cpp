// libFuzzer target for the CSV reader. Anything but clean data or a DataError aborts.
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "fuzz_csv_harness.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string problem =
      valvediag::fuzz::run_csv(std::string_view(reinterpret_cast<const char*>(data), size));
  if (!problem.empty()) {
    std::fprintf(stderr, "fuzz_csv: %s\n", problem.c_str());
    std::abort();
  }
  return 0;
}
