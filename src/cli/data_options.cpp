#include "data_options.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

#include "commands.hpp"
#include "isolated_mat_reader.hpp"
#include "valvediag/io/mat_reader.hpp"
#include "valvediag/sweep/loop_health.hpp"
#include "valvediag/sweep/loop_verdict.hpp"

namespace valvediag::cli {

CLI::Option* add_max_rows_option(CLI::App* cmd, std::size_t& max_rows, const std::string& what) {
  return cmd
      ->add_option(
          "--max-rows", max_rows,
          "refuse " + what + " with more rows than this (it bounds memory, about 50 bytes a row)")
      // An upper end, so that "-3" (read as a huge unsigned number) is refused.
      ->check(CLI::Range(std::size_t{2}, std::size_t{1'000'000'000'000}))
      ->capture_default_str();
}

void add_data_options(CLI::App* cmd, DataOptions& d) {
  const char* g = "Input";
  cmd->add_option("data", d.data,
                  "CSV file with columns t, op, pv (optional sp, mv), or a MATLAB .mat file "
                  "(with --loop PATH when it holds several loops); or use --db and --loop");
  cmd->add_option("--db", d.db, "a recording (valvediag record) instead of a CSV file")->group(g);
  cmd->add_option("--loop", d.loop,
                  "the recorded loop (with --db), or the loop inside a .mat file: its path "
                  "(benchmark.chemicals.loop23, runs(2)) or a matrix variable (m1d14); "
                  "'valvediag import FILE.mat' lists them")
      ->group(g);
  cmd->add_option("--from", d.from, "with --db: start, s from the recording's start")->group(g);
  cmd->add_option("--to", d.to, "with --db: end, s from the recording's start")->group(g);
  add_bridge_gaps_option(cmd, d.bridge_gaps);
  add_layout_options(cmd, d);
}

CLI::Option* add_bridge_gaps_option(CLI::App* cmd, std::size_t& ticks) {
  return cmd
      ->add_option("--bridge-gaps", ticks,
                   "with --db: fill gaps of at most N ticks (missed, lost or bad samples) by "
                   "linear interpolation between the good samples around them, and say where; "
                   "sweep and serve fill 2 (default 0: a range with a gap is refused)")
      ->group("Input");
}

void add_layout_options(CLI::App* cmd, DataOptions& d) {
  const char* g = "Input";
  cmd->add_option("--format", d.format,
                  "CSV layout: 'auto' finds the delimiter, lines before the header and between "
                  "header and data, the time column and its date-time format, decimal comma and "
                  "historian tags (*.MV/*.OP/*.OUT, *.PV, *.SV/*.SP) from the first 200 lines, "
                  "and prints what it chose; options given win. 'plain': only the options")
      ->check(CLI::IsMember({"auto", "plain"}))
      ->group(g)
      ->capture_default_str();
  d.given.t =
      cmd->add_option(
             "--t", d.csv.t_column,
             "time column name or 1-based index; DATE+TIME for a stamp split over a date and "
             "a time-of-day column ('none': no time column)")
          ->group(g)
          ->capture_default_str();
  d.given.op =
      cmd->add_option("--op", d.csv.op_column,
                      "controller output column (.mat: field of the loop struct, or 1-based column "
                      "of a matrix)")
          ->group(g)
          ->capture_default_str();
  d.given.pv = cmd->add_option("--pv", d.csv.pv_column, "process variable column")
                   ->group(g)
                   ->capture_default_str();
  d.given.sp =
      cmd->add_option("--sp", d.csv.sp_column, "set point column ('none' to ignore)")->group(g);
  cmd->add_option("--mv", d.csv.mv_column, "measured valve position column ('none' to ignore)")
      ->group(g);
  d.given.delimiter =
      cmd->add_option("--delimiter", d.csv.delimiter, "',', ';', 'tab', 'space' or 'auto'")
          ->group(g)
          ->capture_default_str();
  d.given.skip_lines =
      cmd->add_option("--skip-lines", d.csv.skip_lines, "lines before the header row")->group(g);
  d.given.skip_after_header = cmd->add_option("--skip-after-header", d.csv.skip_after_header,
                                              "lines between header and data")
                                  ->group(g);
  d.given.time_format = cmd->add_option("--time-format", d.csv.time_format,
                                        "'seconds' or a pattern like '%Y-%m-%d %H:%M:%S'")
                            ->group(g)
                            ->capture_default_str();
  d.given.decimal =
      cmd->add_option("--decimal", d.decimal, "decimal separator in numbers: '.' or ','")
          ->check(CLI::IsMember({".", ","}))
          ->group(g)
          ->capture_default_str();
  cmd->add_flag("--resample", d.csv.resample, "interpolate irregular sampling onto a uniform grid")
      ->group(g);
  add_max_rows_option(cmd, d.csv.max_rows, "data (a CSV or .mat file, a --db range)")->group(g);
  cmd->add_option(
         "--sample-period", d.sample_period,
         "sample period in s (with --resample, without a time column, or for a .mat matrix or "
         "loop without Ts)")
      ->group(g);
}

void add_op_range_option(CLI::App* cmd, std::string& spec) {
  cmd->add_option("--op-range", spec,
                  "the valve's OP span LO:HI in OP units (default 0:100): stiction and valve "
                  "travel are given in % of it")
      ->group("Input");
}

std::vector<double> split_check_shares(double validate, bool split_check) {
  if (!(validate > 0.05 && validate < 0.9)) throw UsageError("--validate must lie in (0.05, 0.9)");
  if (!split_check) return {};
  constexpr double kStep = 0.05;  // how far the check moves the split each way
  if (!(validate - kStep > 0.05 && validate + kStep < 0.9))
    throw UsageError(
        "--split-check scores at --validate -+ 0.05, so --validate must lie in (0.1, 0.85)");
  return {validate - kStep, validate + kStep};
}

OpRange parse_op_range(const std::string& spec) {
  if (spec.empty()) return {};
  const auto colon = spec.find(':');
  OpRange r;
  try {
    if (colon == std::string::npos) throw std::invalid_argument("no colon");
    std::size_t n1 = 0, n2 = 0;
    const std::string lo = spec.substr(0, colon), hi = spec.substr(colon + 1);
    r.lo = std::stod(lo, &n1);
    r.hi = std::stod(hi, &n2);
    if (n1 != lo.size() || n2 != hi.size()) throw std::invalid_argument("trailing text");
  } catch (const std::exception&) {
    throw UsageError("--op-range '" + spec +
                     "': give the valve's OP span as LO:HI in OP units, e.g. 0:100 or 4:20");
  }
  if (!(std::isfinite(r.lo) && std::isfinite(r.hi) && r.lo < r.hi))
    throw UsageError("--op-range '" + spec + "': LO must be below HI, both finite numbers");
  return r;
}

std::string op_range_note(const LoopData& d, const OpRange& range, bool given) {
  if (d.op.empty()) return "";
  const auto [lo, hi] = std::minmax_element(d.op.begin(), d.op.end());
  const double slack = 0.01 * (range.hi - range.lo);
  if (*lo >= range.lo - slack && *hi <= range.hi + slack) return "";
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "OP spans %g .. %g, beyond the OP range %g:%g%s: stiction and valve travel in %% "
                "of travel assume that range; give the valve's OP span with --op-range LO:HI",
                *lo, *hi, range.lo, range.hi, given ? "" : " (the default, OP in %)");
  return buf;
}

LoopData load_data(DataOptions& d, std::vector<std::string>& notes) {
  if (d.data.empty() == d.db.empty())
    throw UsageError("give a CSV or .mat file, or --db site.sqlite --loop NAME (one of them)");
  if (!d.db.empty()) {
    RecordedLoop r = read_db_loop(d.db, d.loop, d.from, d.to, 0, d.csv.max_rows, d.bridge_gaps);
    notes.insert(notes.end(), r.notes.begin(), r.notes.end());
    d.run_read = r.run;
    return std::move(r.data);
  }
  if (d.bridge_gaps > 0)
    throw UsageError("--bridge-gaps goes with --db: a file's gaps are its own");
  const bool mat = is_mat_file(d.data);
  if ((!mat && !d.loop.empty()) || !d.from.empty() || !d.to.empty())
    throw UsageError(mat ? "--from and --to go with --db"
                         : "--loop goes with --db or a .mat file; --from and --to with --db");
  if (!d.sample_period.empty()) {
    try {
      d.csv.sample_period = std::stod(d.sample_period);
    } catch (const std::exception&) {
      throw UsageError("--sample-period must be a number of seconds, got '" + d.sample_period +
                       "'");
    }
  }
  if (mat) {
    const CsvOptions plain;
    const CsvOptions& c = d.csv;
    if (c.delimiter != plain.delimiter || c.skip_lines || c.skip_after_header ||
        c.time_format != plain.time_format || c.resample || d.decimal != ".")
      throw UsageError(d.data +
                       ": --delimiter, --skip-lines, --skip-after-header, --time-format, "
                       "--resample and --decimal are for CSV files, not .mat");
    MatOptions m;
    m.op = c.op_column;
    m.pv = c.pv_column;
    m.sp = c.sp_column;
    m.mv = c.mv_column;
    m.t = c.t_column;
    m.sample_period = c.sample_period;
    m.require_pv = d.require_pv;
    m.max_rows = c.max_rows;
    return read_mat_loop_isolated(d.data, d.loop, m, &notes);
  }
  d.csv.decimal = d.decimal[0];
  d.csv.format = d.format;
  auto given = [](const CLI::Option* o) { return o != nullptr && o->count() > 0; };
  const DataOptions::Given& g = d.given;
  d.csv.given = {given(g.delimiter),   given(g.skip_lines), given(g.skip_after_header),
                 given(g.time_format), given(g.decimal),    given(g.t),
                 given(g.op),          given(g.pv),         given(g.sp)};
  return read_loop_csv(d.data, d.csv, &notes);
}

std::string data_name(const DataOptions& d) {
  if (!d.db.empty()) return d.db + "." + d.loop;
  return d.loop.empty() ? d.data : d.data + "." + d.loop;  // a loop inside a .mat file
}

AnalysedPart analysed_part(const LoopData& whole, bool keep_lead_in, const OpRange& range,
                           std::vector<std::string>& notes) {
  // The data check a sweep makes before it fits anything: the same verdict for one loop.
  std::string unusable = unusable_reason(whole, loop_health(whole, range));
  if (!unusable.empty()) notes.push_back("a sweep would not judge this record: " + unusable);
  VerdictOptions as;
  as.keep_lead_in = keep_lead_in;
  as.range = range;
  const QuietLeadIn lead = lead_in_left_out(whole, as, unusable.empty());
  if (!lead.cut()) return {whole, 0.0, std::move(unusable)};
  notes.push_back(describe_lead_in(lead, whole.t) + " (--keep-lead-in analyses it all)");
  return {drop_lead_in(whole, lead.begin), whole.t[lead.begin] - whole.t.front(),
          std::move(unusable)};
}

}  // namespace valvediag::cli
