// The model history of one data set: every fit of the same data, in order, kept in a small JSON
// file so that `fit --add`, `diagnose --auto` and `ladder` see the same ladder. By default the
// file is in the user's state directory, named by the data's content and how it was read, never
// next to the data (a shared folder of exports, a site database).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "valvediag/io/loop_data.hpp"
#include "valvediag/model/model_fit.hpp"
#include "valvediag/util/utc_time.hpp"  // utc_timestamp(): the entries' time stamps

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

// `<data file>.history.json` (the demo keeps its history beside its own files).
std::string history_path_for(const std::string& data_path);
// $XDG_STATE_HOME/valvediag, else $HOME/.local/state/valvediag (XDG base directories: a relative
// XDG_STATE_HOME is ignored); "" with the reason in `why` when neither is usable.
std::string history_state_dir(std::string& why);
// A 64-bit fingerprint (FNV-1a) of the data as read, values and lengths of every column, and of
// `reading` (the options that read it): the same file read differently is a different history.
std::uint64_t history_key(const LoopData& d, const std::string& reading);
// STATE_DIR/history/KEY.json (KEY in hex): a copy of the data elsewhere, read the same way, has
// the same history.
std::string history_file_in(const std::string& state_dir, std::uint64_t key);
// Empty when the file does not exist; throws std::runtime_error naming the file when it is
// unreadable.
std::vector<HistoryEntry> load_history(const std::string& path);
// Appends and rewrites the file (atomically: a temporary file renamed over it); creates its
// folder (mode 0700). Returns the number of entries now in it.
std::size_t append_history(const std::string& path, const std::vector<HistoryEntry>& entries);
// The same for commands whose result stands without the history (fit, diagnose, report): false
// with the reason in `why` when the file cannot be read or written (a junk file, an unwritable
// state directory), instead of failing the command after its result was printed. `total`: the
// entries now in the file.
bool try_append_history(const std::string& path, const std::vector<HistoryEntry>& entries,
                        std::string& why, std::size_t* total = nullptr);
HistoryEntry history_entry(const ModelFit& fit, const std::string& command);
// One entry as the file holds it (one line of JSON), for a recording's table model_history;
// from_json throws std::runtime_error naming `where` when the text is not an entry.
std::string history_entry_to_json(const HistoryEntry& h);
HistoryEntry history_entry_from_json(const std::string& text, const std::string& where);

}  // namespace valvediag
