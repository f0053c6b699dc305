// libFuzzer target: see fuzz_bus_harness.hpp. Anything but a handled input aborts.
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "fuzz_bus_harness.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string problem =
      valvediag::fuzz::run_codec(std::string_view(reinterpret_cast<const char*>(data), size));
  if (!problem.empty()) {
    std::fprintf(stderr, "fuzz_codec: %s\n", problem.c_str());
    std::abort();
  }
  return 0;
}
