// The data options every analysis command takes: a CSV file with its layout (column remapping,
// historian layout), a loop inside a MATLAB .mat file (--loop PATH; --op/--pv name fields of a
// loop struct or 1-based columns of a matrix) or a recorded loop (--db/--loop/--from/--to),
// registered once here and turned into LoopData.
#pragma once

#include <CLI/CLI.hpp>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "valvediag/core/op_range.hpp"
#include "valvediag/io/csv_reader.hpp"
#include "valvediag/io/loop_data.hpp"

namespace valvediag::cli {

struct DataOptions {
  std::string data;  // a CSV or .mat file; empty when the loop comes from --db
  CsvOptions csv;
  std::string sample_period;
  std::string decimal = ".";
  std::string db, loop, from, to;  // a recorded loop (valvediag record) instead of a file;
                                   // loop also names the loop inside a .mat file
  std::size_t bridge_gaps = 0;     // with --db: gaps of at most this many ticks interpolated
  std::int64_t run_read = 0;       // set by load_data: the run a --db loop was read from
  // "auto" (sniff the CSV layout the options leave open) or "plain"; see CsvOptions::format.
  std::string format = "auto";
  // The layout options as registered, to tell which the user gave (their count()).
  struct Given {
    CLI::Option *delimiter = nullptr, *skip_lines = nullptr, *skip_after_header = nullptr,
                *time_format = nullptr, *decimal = nullptr, *t = nullptr, *op = nullptr,
                *pv = nullptr, *sp = nullptr;
  } given;
  // False: a .mat loop without PV is read with pv empty (a sweep gives its OP figures).
  bool require_pv = true;
};

// --max-rows: the readers' bound on memory, refusing `what` with more rows.
CLI::Option* add_max_rows_option(CLI::App* cmd, std::size_t& max_rows, const std::string& what);
// Adds the positional DATA, --db/--loop/--from/--to and the CSV layout options (group "Input").
void add_data_options(CLI::App* cmd, DataOptions& d);
// --bridge-gaps N: a recording's gaps of at most N ticks interpolated (read_recorded_loop).
CLI::Option* add_bridge_gaps_option(CLI::App* cmd, std::size_t& ticks);
// Only the CSV layout options (columns, delimiter, header lines, time format, ...), for commands
// that take several files (sweep).
void add_layout_options(CLI::App* cmd, DataOptions& d);
// Reads the data from the file or the recording; notes (columns used, time origin, resampling)
// go to `notes`. Wrong combinations (both or neither source, --loop without --db or a .mat file,
// CSV layout options with a .mat file) are UsageErrors.
LoopData load_data(DataOptions& d, std::vector<std::string>& notes);
// --op-range LO:HI, the valve's OP span in OP units (group "Input"): friction and travel figures
// are in % of it. Default 0:100 (OP in %).
void add_op_range_option(CLI::App* cmd, std::string& spec);
// Parses it ("" is 0:100); a UsageError names the option and the expected form.
OpRange parse_op_range(const std::string& spec);
// A note when OP leaves `range` by more than 1 % of it (the figures in % of travel would be
// wrong), "" otherwise.
std::string op_range_note(const LoopData& d, const OpRange& range, bool given);
// The part of `whole` that diagnose, report and a sweep analyse: from a little before OP moves
// when it rests for most of the record (lead_in_left_out() in loop_verdict.hpp), else all of
// it; a note in `notes` says where the analysis starts. from_s: that start, s after the record's
// first sample (0: the whole record). unusable: why a sweep would not judge the record at all
// (unusable_reason() in loop_health.hpp; "" when it would), also a note: the verdict is then
// not-enough-data, as in a sweep.
struct AnalysedPart {
  LoopData data;
  double from_s = 0.0;
  std::string unusable;
};
AnalysedPart analysed_part(const LoopData& whole, bool keep_lead_in, const OpRange& range,
                           std::vector<std::string>& notes);
// --validate F with --split-check (diagnose and sweep): checks F and gives the other held-out
// shares the split check scores at, F -+ 0.05 (none without the check). A UsageError names the
// options and the range.
std::vector<double> split_check_shares(double validate, bool split_check);
// What the data is called in messages and which name its model history hangs off:
// the file, "site.sqlite.FIC101" for a recorded loop, "runs.mat.runs(2)" for a loop of a .mat
// file named with --loop.
std::string data_name(const DataOptions& d);

}  // namespace valvediag::cli
