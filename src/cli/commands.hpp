// Subcommands of the valvediag binary. Each registers itself on the app and returns the exit
// status through the shared Exit value.
#pragma once

#include <CLI/CLI.hpp>
#include <stdexcept>
#include <string>

#include "valvediag/recorder/recorder.hpp"
#include "valvediag/report/html_report.hpp"

namespace valvediag::cli {

// Exit statuses: findings and poor fits are results (0); these are the failures.
enum ExitCode : int {
  kOk = 0,
  kFailure = 1,
  kBadInput = 2,
  kNoModel = 3,
  kRecordedWithErrors = 4  // record: data stored, but some ticks had communication errors
};

// A user error found by a command (bad option combination, bad value): exit status 2.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

void add_fit(CLI::App& app, int& exit_code);
void add_simulate(CLI::App& app, int& exit_code);
void add_demo(CLI::App& app, int& exit_code);
void add_diagnose(CLI::App& app, int& exit_code);
void add_ladder(CLI::App& app, int& exit_code);
void add_sim_plc(CLI::App& app, int& exit_code);
void add_record(CLI::App& app, int& exit_code);
void add_export(CLI::App& app, int& exit_code);
void add_import(CLI::App& app, int& exit_code);
void add_report(CLI::App& app, int& exit_code);
void add_sweep(CLI::App& app, int& exit_code);
void add_sweep_merge(CLI::App& app, int& exit_code);
void add_trend(CLI::App& app, int& exit_code);
void add_serve(CLI::App& app, int& exit_code);

// A loop read from a recording (--db/--loop of export and fit); --from/--to in seconds; gaps of
// at most bridge_ticks ticks interpolated (--bridge-gaps). Other gaps and unknown names are
// UsageErrors, too many rows or an absurd value a DataError (exit status 2).
RecordedLoop read_db_loop(const std::string& db, const std::string& loop, const std::string& from,
                          const std::string& to, std::int64_t run = 0,
                          std::size_t max_rows = kDefaultMaxRows, std::size_t bridge_ticks = 0);
// A duration option ("90s", "10m", "4h"): positive seconds, else a UsageError naming `opt`.
double duration_option(const std::string& opt, const std::string& v);
// "A,B,,C" -> {A, B, C}: the --loops lists of record and sweep.
std::vector<std::string> split_names(const std::string& s);
// --loops of sweep and serve: `name` is one of `wanted`'s names, or matches one of its shell
// patterns (benchmark.chemicals.*); every name when `wanted` is empty.
bool selected(const std::vector<std::string>& wanted, const std::string& name);
// A UsageError for a name or pattern of `wanted` that selects none of `names` (a typo), naming
// `where` and its loops.
void check_selection(const std::vector<std::string>& wanted, const std::vector<std::string>& names,
                     const std::string& where);
// The recorder's end-of-run summary (record and demo).
std::string recorder_summary(const RecorderStatus& s, const std::string& db, std::int64_t run);

// The HTML report (report and demo): --out checked before the long work (a UsageError when the
// file cannot be created), the page written atomically (a temporary file renamed over it).
void check_report_writable(const std::string& path);
struct ReportFile {
  std::size_t bytes = 0, plots = 0;
  double plot_seconds = 0.0;
  std::vector<std::string> warnings;
};
ReportFile write_report_file(const std::string& path, const ReportContent& content,
                             const ReportOptions& opt);
// Any page (html_report, html_data_page) written the same way.
ReportFile write_page_file(const std::string& path, const HtmlReport& rep);
std::string report_file_summary(const std::string& path, const ReportFile& r);

}  // namespace valvediag::cli
