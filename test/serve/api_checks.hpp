// Checks shared by the socket-free API tests.
#pragma once

#include <doctest/doctest.h>

#include "valvediag/serve/workbench_api.hpp"

namespace valvediag::test {

// A refusal: the status, and a JSON body {"error": "..."} with a message.
inline void check_error(const serve::ApiResponse& r, int status) {
  CHECK(r.status == status);
  REQUIRE(r.body.is_object());
  REQUIRE(r.body.contains("error"));
  CHECK(!r.body["error"].get<std::string>().empty());
}

}  // namespace valvediag::test
