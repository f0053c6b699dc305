// Load benchmark of the recorder (a benchmark, not a test): 50 loops with OP, PV, SP at 10 Hz
// from the simulated PLC over loopback Modbus TCP for 60 s (argument 1: seconds), recorded
// through the real driver into SQLite: missed ticks (goal 0), p50/p99 tick lateness. Then the
// same while every core is kept busy (cores + 1 threads of arithmetic: a workbench fit job and the
// laptop's other work beside `serve --config`). Then the SQLite insert rate of the recorder's
// own insert path (goal >= 100,000 samples/s).
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "valvediag/drivers/bus_factory.hpp"
#include "valvediag/drivers/sim_plc.hpp"
#include "valvediag/recorder/recorder.hpp"

using namespace valvediag;
namespace fs = std::filesystem;

namespace {

// One recording of `seconds` into `db`; the figures printed, prefixed by `what`.
void record(const SiteConfig& site, SimPlc& plc, const std::string& db, double seconds,
            const char* what) {
  const auto loops = static_cast<long long>(site.loops.size());
  RecorderOptions o;
  o.db_path = db;
  o.duration_s = seconds;
  Recorder rec(site, o, make_bus);
  std::atomic<bool> stop{false};
  std::printf(
      "load: %lld loops x OP, PV, SP at 10 Hz over loopback Modbus TCP for %.0f s, %s ...\n", loops,
      seconds, what);
  std::fflush(stdout);
  const RecorderStatus s = rec.run(stop);
  const BusStats bs = s.buses.at(0).second;
  std::printf(
      "  ticks recorded    %llu of %llu expected (%llu requests, %llu failed)\n"
      "  missed ticks      %llu (goal 0)\n"
      "  tick lateness     p50 %.2f ms, p99 %.2f ms, max %.2f ms\n"
      "  write requests    %llu (must be 0)\n",
      static_cast<unsigned long long>(s.rows),
      static_cast<unsigned long long>(loops * static_cast<long long>(seconds * 10 + 0.5)),
      static_cast<unsigned long long>(bs.requests), static_cast<unsigned long long>(bs.errors),
      static_cast<unsigned long long>(s.missed), s.lateness_p50_s * 1e3, s.lateness_p99_s * 1e3,
      s.lateness_max_s * 1e3, static_cast<unsigned long long>(plc.write_requests()));
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::atof(argv[1]) : 60.0;
  const int loops = 50;
  const fs::path dir = fs::temp_directory_path() / "valvediag-load-bench";
  fs::remove_all(dir);
  fs::create_directories(dir);

  std::string toml =
      "[[bus]]\nname = \"plc\"\nprotocol = \"modbus-tcp\"\ncontroller = "
      "\"tcp://127.0.0.1\"\ntimeout = \"200ms\"\nretries = 0\n";
  for (int i = 0; i < loops; ++i) {
    const int a = 8 * i;
    char b[512];
    std::snprintf(b, sizeof b,
                  "[[loop]]\nname = \"L%02d\"\nbus = \"plc\"\nsimulate = \"paper-ex1\"\nseed = %d\n"
                  "sample_period = \"100ms\"\n"
                  "op = { address = %d, type = \"FLOAT32\" }\n"
                  "pv = { address = %d, type = \"FLOAT32\" }\n"
                  "sp = { address = %d, type = \"FLOAT32\" }\n",
                  i, i + 1, a, a + 2, a + 4);
    toml += b;
  }
  SiteConfig site = parse_site_config(toml, "load bench site");
  // paper-ex1 steps every 0.5 s of plant time: 5x real time gives the 10 Hz of the registers.
  SimPlc plc(site, SimPlcOptions{5.0, 0});
  plc.start();
  for (auto& b : site.buses) b.port = plc.port();

  record(site, plc, (dir / "load.sqlite").string(), seconds, "the cores idle");
  {
    // The simulated PLC shares the busy cores too, so its replies slow as well: an upper bound.
    const unsigned busy = std::max(1u, std::thread::hardware_concurrency()) + 1;
    std::atomic<bool> done{false};
    std::vector<std::thread> spin;
    for (unsigned k = 0; k < busy; ++k)
      spin.emplace_back([&done, k] {
        volatile double x = 1.0 + k;
        while (!done.load(std::memory_order_relaxed)) x = std::sqrt(x * x + 1.0);
      });
    const std::string what = std::to_string(busy) + " threads keeping every core busy";
    record(site, plc, (dir / "load_busy.sqlite").string(), seconds, what.c_str());
    done = true;
    for (auto& t : spin) t.join();
  }
  plc.stop();

  // Insert rate: the recorder's insert path, one transaction per batch of one "second" at the
  // load above scaled up (10,000 rows of 5 values each per transaction).
  RecordingDb db((dir / "insert.sqlite").string());
  const std::int64_t run = db.begin_run("bench");
  LoopConfigEntry l = site.loops[0];  // a copy: g++ 12 warns falsely on assigning a short literal
  const std::int64_t id = db.add_loop(run, l);
  const std::size_t batch = 10000, batches = 50;
  std::vector<SampleRow> rows(batch);
  const auto t0 = std::chrono::steady_clock::now();
  for (std::size_t k = 0; k < batches; ++k) {
    for (std::size_t i = 0; i < batch; ++i) {
      SampleRow& r = rows[i];
      r.loop_id = id;
      r.tick = static_cast<std::int64_t>(k * batch + i);
      r.wall = 1.7e9 + static_cast<double>(r.tick) * 0.1;
      for (std::size_t p = 0; p < 3; ++p)
        r.values[p] = {50.0 + static_cast<double>(i % 97), Quality::good};
    }
    db.insert(rows);
  }
  const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double n = static_cast<double>(batch * batches);
  std::printf(
      "  SQLite inserts    %.0f rows/s = %.0f samples/s of OP, PV, SP (goal >= 100,000 "
      "samples/s; %zu rows per transaction, WAL)\n",
      n / dt, 3 * n / dt, batch);
  fs::remove_all(dir);
  return 0;
}
