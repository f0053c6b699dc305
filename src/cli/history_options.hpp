// Where a command keeps the data's model history (model_history.hpp): --history FILE; else for a
// recording (--db) its table model_history (recording_history.hpp); else the user's state
// directory, never next to the data; --no-history writes none.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "data_options.hpp"
#include "valvediag/recorder/recording_history.hpp"
#include "valvediag/report/model_history.hpp"

namespace valvediag::cli {

struct HistoryOptions {
  std::string file;  // --history
  bool off = false;  // --no-history (commands that write one)
};

// The history of one data set: a JSON file, or a recording's table with the state directory's
// file as the fallback when the database cannot take an entry (read-only, busy).
struct HistoryPlace {
  std::string file;  // "" when there is none
  std::string db;    // a recording: the entries in its table model_history under `key`
  RecordingHistoryKey key;
  bool empty() const { return file.empty() && db.empty(); }
  // For messages: "site.sqlite (table model_history)", or the file.
  std::string where() const;
};

// --history FILE, and --no-history when the command writes to the history (group `group`).
void add_history_options(CLI::App* cmd, HistoryOptions& h, const char* group, bool writes = true);
// The options that turned the file into `d` (columns, delimiter, loop, time range, ...), one
// string: part of the history's key.
std::string reading_options(const DataOptions& d);
// The history of `data` as `d` read it: --history; else a recording's table; else the state
// directory's file for its content and reading options. Empty when there is no state directory:
// a warning on stderr says why (not with --no-history) and the command goes on without one.
HistoryPlace history_place(const HistoryOptions& h, const DataOptions& d, const LoopData& data);
// The entries of `p`, oldest first ({} for an empty place): a recording's table and, when it
// holds some, the fallback file. Throws std::runtime_error naming what cannot be read.
std::vector<HistoryEntry> load_history_at(const HistoryPlace& p);
// The same, but what cannot be read is a warning on stderr, {}, and `p` cleared: it is left as
// it is, not rewritten.
std::vector<HistoryEntry> read_history_or_warn(HistoryPlace& p);
// What adding entries to a history did: where they went and how many the history now holds, or
// why they could not be kept (`total` 0, `where` empty); `warnings`: a recording that could not
// take them, whose fallback file did.
struct HistoryAppended {
  std::string where;
  std::size_t total = 0;
  std::string error;
  std::vector<std::string> warnings;
};
// Adds `entries` to `p` (a recording's table, else or when it cannot take them the file).
// Nothing to do (`p` or `entries` empty): an empty result.
HistoryAppended append_history_at(const HistoryPlace& p, const std::vector<HistoryEntry>& entries);
// Adds `entries` to `p` and says where on stdout ("model history: PATH (3 fits)"), or warns on
// stderr that `result` stands without it. A recording that cannot take them (read-only, busy for
// a second) is a warning and the fallback file takes them. Nothing when `p` is empty or the list
// is.
void record_history(const HistoryPlace& p, const std::vector<HistoryEntry>& entries,
                    const std::string& result);

}  // namespace valvediag::cli
