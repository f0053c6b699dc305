// Sweep results in the site database (next to the recordings): one row per sweep, one per loop
// and sweep with the figures as columns and the whole result as JSON, so each loop's trend over
// past sweeps can be read back. Each result is committed as it arrives: a killed sweep keeps
// every loop it finished.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "valvediag/recorder/recorder.hpp"
#include "valvediag/recorder/schema_versions.hpp"
#include "valvediag/report/sweep_report.hpp"
#include "valvediag/sweep/loop_assessment.hpp"

namespace valvediag {

// Version of the sweep tables this build writes; older databases are migrated when opened,
// newer ones refused.
inline constexpr int kSweepSchemaVersion = 2;
inline constexpr SchemaTables kSweepTables{"sweeps", "sweeps", "sweep", kSweepSchemaVersion};

struct TrendPoint {
  std::int64_t sweep = 0;
  std::string started_utc;
  double validation_fraction = 0.3;  // held out for scoring: fitness compares only at equal share
  LoopAssessment result;
};

// Throws std::runtime_error naming the file and what to do on any SQLite failure.
class SweepStore {
 public:
  enum class Access { ReadWrite, ReadOnly };
  // ReadWrite creates the file or migrates its tables; ReadOnly (trend) writes nothing, so a
  // read-only copy of a site database can be read: it refuses tables it would have to migrate,
  // and a file without sweep tables gives empty trends.
  explicit SweepStore(const std::string& db_path, Access access = Access::ReadWrite);
  ~SweepStore();
  SweepStore(const SweepStore&) = delete;
  SweepStore& operator=(const SweepStore&) = delete;

  std::int64_t begin_sweep(const SweepInfo& info);
  void add_result(std::int64_t sweep, const LoopAssessment& a);
  void end_sweep(std::int64_t sweep, const SweepInfo& info, const std::string& status);
  // The loop's results over the last `last` sweeps that assessed it, oldest first.
  std::vector<TrendPoint> trend(const std::string& loop, int last = 10);
  // Names of the loops any sweep assessed.
  std::vector<std::string> assessed_loops();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// End of the latest recording of `loop` (of run `run`; 0: the latest run that recorded it) in
// seconds from its run's start (last tick + one period), or nullopt when the database holds no
// sample of it.
std::optional<double> recorded_end_s(const std::string& db_path, const std::string& loop,
                                     std::int64_t run = 0);
// The latest `window_s` seconds recorded of `loop` (of run `run`, 0: the latest), as the
// analysis reads them: short gaps bridged, the longest clean stretch when gaps are left
// (read_recorded_loop with kBridgedTicks). nullopt when nothing is recorded; read_recorded_loop's
// errors otherwise (std::runtime_error: nothing clean in the window; DataError: too many rows).
std::optional<RecordedLoop> read_latest_window(const std::string& db_path, const std::string& loop,
                                               double window_s, std::size_t max_rows,
                                               std::int64_t run = 0);

}  // namespace valvediag
