// The OP span a valve travels over. Header-only and without dependencies, so that the
// identification core, the diagnosis and the sweep share one type for it.
#pragma once

namespace valvediag {

struct OpRange {
  double lo = 0.0, hi = 100.0;  // the OP span the valve travels over, in OP units
  bool operator==(const OpRange&) const = default;
};

}  // namespace valvediag
