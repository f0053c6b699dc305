#include "data_options.hpp"

#include "commands.hpp"

namespace valvediag::cli {

void add_data_options(CLI::App* cmd, DataOptions& d) {
  const char* g = "Input";
  cmd->add_option("data", d.data,
                  "CSV file with columns t, op, pv (optional sp, mv); or use --db and --loop");
  cmd->add_option("--db", d.db, "a recording (valvediag record) instead of a CSV file")->group(g);
  cmd->add_option("--loop", d.loop, "the recorded loop (with --db)")->group(g);
  cmd->add_option("--from", d.from, "with --db: start, s from the recording's start")->group(g);
  cmd->add_option("--to", d.to, "with --db: end, s from the recording's start")->group(g);
  cmd->add_option("--t", d.csv.t_column,
                  "time column name or 1-based index ('none': no time column)")
      ->group(g)
      ->capture_default_str();
  cmd->add_option("--op", d.csv.op_column, "controller output column")
      ->group(g)
      ->capture_default_str();
  cmd->add_option("--pv", d.csv.pv_column, "process variable column")
      ->group(g)
      ->capture_default_str();
  cmd->add_option("--sp", d.csv.sp_column, "set point column ('none' to ignore)")->group(g);
  cmd->add_option("--mv", d.csv.mv_column, "measured valve position column ('none' to ignore)")
      ->group(g);
  cmd->add_option("--delimiter", d.csv.delimiter, "',', ';', 'tab', 'space' or 'auto'")
      ->group(g)
      ->capture_default_str();
  cmd->add_option("--skip-lines", d.csv.skip_lines, "lines before the header row")->group(g);
  cmd->add_option("--skip-after-header", d.csv.skip_after_header, "lines between header and data")
      ->group(g);
  cmd->add_option("--time-format", d.csv.time_format,
                  "'seconds' or a pattern like '%Y-%m-%d %H:%M:%S'")
      ->group(g)
      ->capture_default_str();
  cmd->add_option("--decimal", d.decimal, "decimal separator in numbers: '.' or ','")
      ->check(CLI::IsMember({".", ","}))
      ->group(g)
      ->capture_default_str();
  cmd->add_flag("--resample", d.csv.resample, "interpolate irregular sampling onto a uniform grid")
      ->group(g);
  cmd->add_option("--sample-period", d.sample_period,
                  "sample period in s (with --resample or without a time column)")
      ->group(g);
}

LoopData load_data(DataOptions& d, std::vector<std::string>& notes) {
  if (d.data.empty() == d.db.empty())
    throw UsageError("give a CSV file or --db site.sqlite --loop NAME (one of them)");
  if (!d.db.empty()) {
    RecordedLoop r = read_db_loop(d.db, d.loop, d.from, d.to);
    notes.insert(notes.end(), r.notes.begin(), r.notes.end());
    return std::move(r.data);
  }
  if (!d.loop.empty() || !d.from.empty() || !d.to.empty())
    throw UsageError("--loop, --from and --to go with --db");
  if (!d.sample_period.empty()) {
    try {
      d.csv.sample_period = std::stod(d.sample_period);
    } catch (const std::exception&) {
      throw UsageError("--sample-period must be a number of seconds, got '" + d.sample_period +
                       "'");
    }
  }
  d.csv.decimal = d.decimal[0];
  return read_loop_csv(d.data, d.csv, &notes);
}

std::string data_name(const DataOptions& d) {
  return d.db.empty() ? d.data : d.db + "." + d.loop;
}

}  // namespace valvediag::cli
