#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>

#include "commands.hpp"
#include "stop_signal.hpp"
#include "valvediag/drivers/bus_factory.hpp"
#include "valvediag/recorder/recorder.hpp"

namespace valvediag::cli {

std::vector<std::string> split_names(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

namespace {

std::string ms(double s) {
  char b[32];
  std::snprintf(b, sizeof b, "%.1f ms", s * 1e3);
  return b;
}

// "1640 samples (0.2 MB)": rows held in memory while the database is busy.
std::string in_memory(std::uint64_t rows) {
  char b[64];
  std::snprintf(b, sizeof b, "%llu samples (%.1f MB)", static_cast<unsigned long long>(rows),
                static_cast<double>(rows * sizeof(SampleRow)) / 1e6);
  return b;
}

std::string status_line(const RecorderStatus& s) {
  std::ostringstream o;
  char t[32];
  std::snprintf(t, sizeof t, "%7.1f s", s.elapsed_s);
  o << "[" << t << "] " << s.loops.size() << " loops, " << s.rows << " samples (" << s.committed
    << " stored), " << s.bad_rows << " with errors, " << s.missed << " missed, lateness p50 "
    << ms(s.lateness_p50_s) << " p99 " << ms(s.lateness_p99_s);
  for (const auto& [name, b] : s.buses) o << ", " << name << (b.connected ? " up" : " DOWN");
  if (s.busy_s > 0) {
    std::snprintf(t, sizeof t, "%.1f s", s.busy_s);
    o << "; database busy " << t << " (locked by another process): " << in_memory(s.waiting)
      << " wait in memory";
  }
  return o.str();
}

}  // namespace

std::string recorder_summary(const RecorderStatus& s, const std::string& db, std::int64_t run) {
  std::ostringstream o;
  char t[32];
  std::snprintf(t, sizeof t, "%.1f", s.elapsed_s);
  o << "recorded " << s.loops.size() << " loop(s) for " << t << " s into " << db << " (run " << run
    << "): " << s.committed << " samples, " << s.bad_rows << " with errors, " << s.missed
    << " missed ticks\n";
  for (const auto& l : s.loops)
    o << "  " << l.name << ": " << l.rows << " samples, " << l.good << " good, " << l.comm_error
      << " comm-error, " << l.stale << " stale, " << l.invalid << " invalid, " << l.missed
      << " missed; " << l.gaps << " gap(s)\n";
  for (const auto& [name, b] : s.buses)
    o << "  bus " << name << ": " << b.requests << " requests, " << b.errors << " failed ("
      << b.timeouts << " timeouts, " << b.exceptions << " exceptions, " << b.garbled
      << " garbled), " << b.disconnects << " disconnects, " << b.reconnects << " reconnects, "
      << b.connect_attempts
      << " connection attempt(s)"
      // A bus that never answered sent no request: say why its loops hold comm-errors.
      << (b.connected ? "" : "; not connected at the end (last error below)") << "\n";
  o << "  lateness of the reads: p50 " << ms(s.lateness_p50_s) << ", p99 " << ms(s.lateness_p99_s)
    << ", max " << ms(s.lateness_max_s) << "\n";
  if (s.busy_times > 0) {
    std::snprintf(t, sizeof t, "%.1f", s.busy_longest_s);
    o << "  database busy " << s.busy_times << " time(s), longest " << t
      << " s (locked by another process; SQLite does not say which): up to "
      << in_memory(s.waiting_peak) << " waited in memory, then were stored\n";
  }
  if (!s.last_error.empty()) o << "  last error: " << s.last_error << "\n";
  return o.str();
}

void add_record(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "record", "Record OP, PV, SP of control loops from the field bus into SQLite (reads only)");
  cmd->footer(
      "Examples:\n"
      "  valvediag record --config configs/site.toml --db site.sqlite\n"
      "  valvediag record --config site.toml --db site.sqlite --loops FIC101,LIC201 --duration "
      "10m\n"
      "One row per sample tick per loop, with a quality flag per value (good, stale, comm-error, "
      "missed, invalid);\ngaps are marked, never filled. Ctrl-C stops cleanly. Exit status 0: no "
      "errors; 4: recorded, with errors\n(see the summary); 2: bad config or options, or the "
      "database is being recorded by another\nrecorder (named; it holds DB.lock while it runs); "
      "1: the database failed (e.g. busy for over 90 s:\nsamples wait in memory while another "
      "process holds its write lock). Only reads: no Modbus write\nfunction code, no CAN frame.");
  struct Args {
    std::string config, db, loops, duration;
    bool quiet = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--config", a->config, "site TOML (configs/site.toml documents it)")->required();
  cmd->add_option("--db", a->db, "SQLite file (created if missing; runs are appended)")->required();
  cmd->add_option("--loops", a->loops, "comma-separated loop names (default: all)");
  cmd->add_option("--duration", a->duration, "stop after this long: 30s, 10m, 2h");
  cmd->add_flag("--quiet", a->quiet, "no live status line");
  cmd->callback([a, &exit_code] {
    RecorderOptions o;
    o.db_path = a->db;
    o.loops = split_names(a->loops);
    if (!a->duration.empty()) {
      o.duration_s = parse_duration(a->duration);
      if (!o.duration_s || *o.duration_s <= 0)
        throw UsageError("--duration '" + a->duration + "': give e.g. 30s, 10m or 2h");
    }
    SiteConfig site = load_site_config(a->config);  // every config error before any traffic
    auto& stop = install_stop_signals();
    std::unique_ptr<Recorder> rec_ptr;
    try {
      rec_ptr = std::make_unique<Recorder>(std::move(site), o, make_bus);
    } catch (const std::runtime_error& e) {
      throw UsageError(e.what());  // no SocketCAN, database not writable: nothing recorded
    }
    Recorder& rec = *rec_ptr;
    const bool tty = ::isatty(2) != 0;
    std::size_t noted = 0;  // a busy database at the start: they are marked once it is free
    auto note_interrupted = [&] {
      for (; noted < rec.interrupted_runs().size(); ++noted)
        std::cerr << "note: run " << rec.interrupted_runs()[noted] << " in " << a->db
                  << " was left 'recording' by a recorder that did not end cleanly (killed, or "
                     "stopped by an error): marked 'interrupted'\n";
    };
    note_interrupted();
    if (!rec.database_ready())
      std::cerr << "note: " << a->db
                << " is busy: another process holds SQLite's write lock (SQLite cannot say "
                   "which; fuser "
                << a->db
                << " may). Polling starts now; the samples wait in memory and are stored once "
                   "it is free (up to "
                << std::lround(o.busy_limit_s) << " s)\n";
    std::cerr << "recording into " << a->db << "; Ctrl-C stops\n";
    const RecorderStatus s = rec.run(stop, [&](const RecorderStatus& st) {
      if (a->quiet) return;
      if (tty)
        std::cerr << "\r" << status_line(st) << "   " << std::flush;
      else
        std::cerr << status_line(st) << "\n";
    });
    if (tty && !a->quiet) std::cerr << "\n";
    note_interrupted();
    std::cout << recorder_summary(s, a->db, rec.run_id());
    exit_code = s.errors() ? kRecordedWithErrors : kOk;
  });
}

}  // namespace valvediag::cli
