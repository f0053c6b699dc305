#include "valvediag/drivers/bus.hpp"

namespace valvediag {

std::string to_string(Quality q) {
  switch (q) {
    case Quality::good:
      return "good";
    case Quality::stale:
      return "stale";
    case Quality::comm_error:
      return "comm-error";
    case Quality::missed:
      return "missed";
    case Quality::invalid:
      return "invalid";
  }
  return "?";
}

}  // namespace valvediag
