// The model history of one data set: every fit of the same data, in order, kept in a small JSON
// file next to the data so that `fit --add`, `diagnose --auto` and `ladder` see the same ladder.
#pragma once

#include <string>
#include <vector>

#include "valvediag/model_fit.hpp"

namespace valvediag {

struct HistoryEntry {
  std::string model;  // spec, e.g. "stiction+saturation"
  double fitness_percent = 0.0;
  double validation_fitness_percent = 0.0;  // NaN without a split
  std::vector<NamedValue> parameters;       // effect parameters, "effect.name"
  int na = 0, nb = 0, nk = 0;
  std::string command;  // what produced it ("fit", "diagnose --auto")
  std::string time;     // UTC, ISO 8601
};

// `<data file>.history.json`
std::string history_path_for(const std::string& data_path);
// Empty when the file does not exist; throws std::runtime_error naming the file when it is
// unreadable.
std::vector<HistoryEntry> load_history(const std::string& path);
// Appends and rewrites the file (atomically: a temporary file renamed over it).
void append_history(const std::string& path, const std::vector<HistoryEntry>& entries);
// The same for commands whose result stands without the history (fit, diagnose, report): false
// with the reason in `why` when the file cannot be read or written (a read-only data folder),
// instead of failing the command after its result was printed.
bool try_append_history(const std::string& path, const std::vector<HistoryEntry>& entries,
                        std::string& why);
HistoryEntry history_entry(const ModelFit& fit, const std::string& command);
// Now, UTC, ISO 8601 (the entries' time stamps).
std::string utc_timestamp();

}  // namespace valvediag
