#include <iostream>

#include "commands.hpp"
#include "data_options.hpp"
#include "valvediag/io/csv_writer.hpp"
#include "valvediag/io/data_error.hpp"
#include "valvediag/recorder/recorder.hpp"

namespace valvediag::cli {

RecordedLoop read_db_loop(const std::string& db, const std::string& loop, const std::string& from,
                          const std::string& to, std::int64_t run, std::size_t max_rows,
                          std::size_t bridge_ticks) {
  auto seconds = [](const std::string& opt, const std::string& v) -> std::optional<double> {
    if (v.empty()) return std::nullopt;
    try {
      std::size_t pos = 0;
      const double x = std::stod(v, &pos);
      if (pos == v.size() && x >= 0) return x;
    } catch (const std::exception&) {
    }
    throw UsageError(opt + " '" + v + "': give seconds from the start of the recording");
  };
  if (loop.empty()) throw UsageError("--db needs --loop NAME");
  try {
    return read_recorded_loop(db, loop, seconds("--from", from), seconds("--to", to), run, false,
                              bridge_ticks, max_rows);
  } catch (const DataError&) {
    throw;  // names the run, loop and tick already
  } catch (const RecordingGapError& e) {
    throw UsageError(std::string(e.what()) +
                     "; or fill the short ones by linear interpolation with --bridge-gaps N "
                     "(ticks; sweep and serve fill " +
                     std::to_string(kBridgedTicks) + ")");
  } catch (const std::runtime_error& e) {
    throw UsageError(e.what());  // no such file, loop or run: the user's input
  }
}

void add_export(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("export", "Write a recorded loop as CSV (t, op, pv, sp)");
  cmd->footer(
      "Examples:\n"
      "  valvediag export --db site.sqlite --loop FIC101 --out fic101.csv\n"
      "  valvediag export --db site.sqlite --loop FIC101 --from 600 --to 1800 --out part.csv\n"
      "  valvediag export --db site.sqlite --loop FIC101 --run 2 --out run2.csv\n"
      "t is in seconds from the start of the recording. Ranges with gaps (ticks without good OP "
      "and PV) are refused,\nnaming the gaps and the longest clean stretch, unless --bridge-gaps "
      "N fills those of at most N ticks.\nWhich run is read is "
      "said on stderr, with the loop's\nother runs; a --run that does not hold the loop lists "
      "them.");
  struct Args {
    std::string db, loop, from, to, out;
    std::int64_t run = 0;
    std::size_t max_rows = kDefaultMaxRows;
    std::size_t bridge_gaps = 0;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--db", a->db, "SQLite recording")->required();
  cmd->add_option("--loop", a->loop, "loop name")->required();
  cmd->add_option("--from", a->from, "start, s from the recording's start");
  cmd->add_option("--to", a->to, "end, s from the recording's start");
  cmd->add_option("--run", a->run,
                  "recording run (default: the latest with this loop; stderr names the others)");
  cmd->add_option("--out", a->out, "CSV file to write")->required();
  // The reader's bound on memory; its refusal names this option, so export must take it.
  add_max_rows_option(cmd, a->max_rows, "a range");
  add_bridge_gaps_option(cmd, a->bridge_gaps);
  cmd->callback([a, &exit_code] {
    const RecordedLoop r =
        read_db_loop(a->db, a->loop, a->from, a->to, a->run, a->max_rows, a->bridge_gaps);
    // Several runs (two recorders once, or one run after another) must not be merged silently.
    std::cerr << "export: loop " << a->loop << " of run " << r.run << " (started "
              << r.run_info.started_utc << ", " << r.run_info.status
              << (r.run_info.status == "recording" ? ": still being recorded, read so far" : "")
              << ")";
    std::string others;
    for (const RunInfo& x : r.runs)
      if (x.id != r.run) others += (others.empty() ? "" : ", ") + std::to_string(x.id);
    if (!others.empty()) std::cerr << "; other runs with it: " << others << " (--run ID)";
    std::cerr << "\n";
    for (const auto& n : r.notes) std::cout << "note: " << n << "\n";
    write_loop_csv(a->out, r.data);
    std::cout << "wrote " << a->out << ": " << r.data.size() << " samples of loop " << a->loop
              << " (run " << r.run << ", Ts " << r.sample_period << " s)\n";
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
