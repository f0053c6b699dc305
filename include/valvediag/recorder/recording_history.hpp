// The model history of a recorded loop kept in its recording (table model_history): a loop
// recorded in site.sqlite has its ladder there, beside its samples, whoever fits it. The entries
// are stored as text (one JSON object each, as model_history.hpp writes them); this file only
// stores and finds them.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "valvediag/recorder/schema_versions.hpp"

namespace valvediag {

inline constexpr int kModelHistorySchemaVersion = 1;
inline constexpr SchemaTables kModelHistoryTables{"model_history", "model_history", "model history",
                                                  kModelHistorySchemaVersion};

// Which history: the run and loop read, and how (`reading`: "" for the whole run, else e.g.
// "--from 600 --to 1800").
struct RecordingHistoryKey {
  std::int64_t run = 0;
  std::string loop, reading;
};

struct StoredHistoryEntry {
  std::string model, time, json;  // model and time in columns of their own, for people using SQL
};

// The entries' JSON texts, oldest first; {} when the file has no model_history table. Opens the
// database read-only. Throws std::runtime_error naming the file when it cannot be read.
std::vector<std::string> load_recording_history(const std::string& db_path,
                                                const RecordingHistoryKey& key);
// Adds `entries` in one short transaction, waiting at most `busy_s` for another process's write
// lock (a recorder commits every half second and holds samples in memory while it waits, so a
// short transaction never costs it a sample). Creates the table the first time. Returns the
// number of entries the key now has. Throws DatabaseBusyError (recorder.hpp) when the lock stays
// taken, std::runtime_error naming the file when it is read-only or cannot be written; then
// nothing was added.
std::size_t append_recording_history(const std::string& db_path, const RecordingHistoryKey& key,
                                     const std::vector<StoredHistoryEntry>& entries,
                                     double busy_s = 1.0);

}  // namespace valvediag
