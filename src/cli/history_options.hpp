// Where a command keeps the data's model history (model_history.hpp): --history FILE, else the
// user's state directory, never next to the data; --no-history writes none.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "data_options.hpp"
#include "valvediag/model_history.hpp"

namespace valvediag::cli {

struct HistoryOptions {
  std::string file;  // --history
  bool off = false;  // --no-history (commands that write one)
};

// --history FILE, and --no-history when the command writes to the history (group `group`).
void add_history_options(CLI::App* cmd, HistoryOptions& h, const char* group, bool writes = true);
// The options that turned the file into `d` (columns, delimiter, loop, time range, ...), one
// string: part of the history's key.
std::string reading_options(const DataOptions& d);
// The history file of `data` as `d` read it: --history, else the state directory's file for its
// content and reading options. "" when there is no state directory: a warning on stderr says why
// (not with --no-history) and the command goes on without a history.
std::string history_file(const HistoryOptions& h, const DataOptions& d, const LoopData& data);
// The entries of `path` ({} for ""); a file that cannot be read is a warning on stderr, {}, and
// `path` cleared: the file is left as it is, not rewritten.
std::vector<HistoryEntry> read_history_or_warn(std::string& path);
// Adds `entries` to `path` and says where on stdout ("model history: PATH (3 fits)"), or warns on
// stderr that `result` stands without it. Nothing when `path` is "" or the list is empty.
void record_history(const std::string& path, const std::vector<HistoryEntry>& entries,
                    const std::string& result);

}  // namespace valvediag::cli
