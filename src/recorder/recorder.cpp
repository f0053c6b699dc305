// Polling threads (one per bus: a bus answers one request at a time) produce rows into a queue;
// the calling thread commits the queue every commit interval and reports status.
#include "valvediag/recorder/recorder.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <optional>
#include <thread>

#include "valvediag/recorder/recorder_lock.hpp"
#include "valvediag/util/text_stats.hpp"
#include "valvediag/util/utc_time.hpp"

namespace valvediag {

namespace {
using Clock = std::chrono::steady_clock;

double since(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

double wall_now() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

struct PolledLoop {
  LoopConfigEntry cfg;
  std::int64_t db_id = 0;
  std::size_t bus_index = 0;  // position on its bus
  std::int64_t next_tick = 0;
  std::int64_t end_tick = std::numeric_limits<std::int64_t>::max();  // exclusive
  // Gap being tracked: first bad tick, or -1.
  std::int64_t gap_start = -1, gap_last = -1;
  std::string gap_reason;
};

struct BusWorker {
  std::unique_ptr<Bus> bus;
  std::vector<std::size_t> loops;  // indices into Impl::loops
  std::thread thread;
};
}  // namespace

struct Recorder::Impl {
  SiteConfig site;
  RecorderOptions opt;
  BusFactory factory;
  std::unique_ptr<RecorderLock> db_lock;  // released after the database is closed
  std::unique_ptr<RecordingDb> db;
  std::vector<std::int64_t> interrupted;
  bool interrupted_marked = false;
  std::int64_t run = 0;
  std::string started_utc;  // when run() began: the run's start however long the database waits
  bool ready = false;       // tables, run and loops in the database: rows can be stored
  std::vector<PolledLoop> loops;
  std::vector<BusWorker> workers;

  std::mutex mutex;  // queue, counts, lateness, gaps, last_error
  std::vector<SampleRow> queue;
  std::vector<LoopCounts> counts;
  std::vector<double> lateness;
  std::uint64_t rows = 0, committed = 0, bad_rows = 0, missed = 0;
  double lateness_max = 0.0;
  std::string last_error;
  std::vector<GapRow> closed_gaps;

  // Commit thread only: taken from the queue, not yet stored (the database was busy). Rows and
  // gaps are produced with the loop's index in `loops` as loop_id (polling starts before the
  // database may have the loops); the first `mapped` carry the database's id.
  std::vector<SampleRow> pending;
  std::vector<GapRow> pending_gaps;
  std::size_t mapped = 0, mapped_gaps = 0;
  std::optional<Clock::time_point> busy_since;
  double busy_longest = 0.0;
  std::uint64_t busy_times = 0, waiting_peak = 0;
  std::string busy_message;

  // Under the mutex: counts and gap tracking for one finished row.
  void account(PolledLoop& l, std::size_t li, const SampleRow& r, const std::string& error) {
    LoopCounts& c = counts[li];
    ++c.rows;
    ++rows;
    const Quality qo = r.values[0].quality, qp = r.values[1].quality;
    const bool good = qo == Quality::good && qp == Quality::good;
    for (std::size_t i = 0; i < 2; ++i) {
      switch (r.values[i].quality) {
        case Quality::good:
          break;
        case Quality::stale:
          ++c.stale;
          break;
        case Quality::comm_error:
          ++c.comm_error;
          break;
        case Quality::missed:
          ++c.missed;
          break;
        case Quality::invalid:
          ++c.invalid;
          break;
      }
      if (r.values[i].quality != Quality::good) break;  // count a row once
    }
    if (good) {
      ++c.good;
      if (l.gap_start >= 0) {
        closed_gaps.push_back(
            {static_cast<std::int64_t>(li), l.gap_start, l.gap_last, l.gap_reason});
        ++c.gaps;
        l.gap_start = -1;
      }
    } else {
      ++bad_rows;
      if (qo == Quality::missed) ++missed;
      if (l.gap_start < 0) {
        l.gap_start = r.tick;
        l.gap_reason = error.empty() ? to_string(qo != Quality::good ? qo : qp) : error;
      }
      l.gap_last = r.tick;
      if (!error.empty()) last_error = l.cfg.name + ": " + error;
    }
    queue.push_back(r);
  }

  void poll(BusWorker& w, Clock::time_point t0, const std::atomic<bool>& stop,
            const std::atomic<bool>& done) {
    while (!stop.load() && !done.load()) {
      // The loop due first (ties: the configured order).
      PolledLoop* next = nullptr;
      std::size_t next_li = 0;
      Clock::time_point due = Clock::time_point::max();
      for (std::size_t li : w.loops) {
        PolledLoop& l = loops[li];
        if (l.next_tick >= l.end_tick) continue;
        const auto d =
            t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(
                     static_cast<double>(l.next_tick) * l.cfg.sample_period_s));
        if (d < due) {
          due = d;
          next = &l;
          next_li = li;
        }
      }
      if (!next) return;  // every loop reached the end of the duration
      if (Clock::now() < due) {
        // Sleep in slices so a stop request is seen within 50 ms.
        std::this_thread::sleep_until(std::min(due, Clock::now() + std::chrono::milliseconds(50)));
        continue;
      }
      PolledLoop& l = *next;
      const auto start = Clock::now();
      const double P = l.cfg.sample_period_s;
      // The current tick; the ones skipped since the last poll are marked missed.
      auto k_now = static_cast<std::int64_t>(std::floor(since(t0, start) / P));
      k_now = std::min(std::max(k_now, l.next_tick), l.end_tick - 1);
      std::unique_lock lock(mutex);
      for (std::int64_t k = l.next_tick; k < k_now; ++k) {
        SampleRow r;
        r.loop_id = static_cast<std::int64_t>(next_li);
        r.tick = k;
        r.wall = wall_now();
        r.lateness = since(t0, start) - static_cast<double>(k) * P;
        for (auto& v : r.values) v.quality = Quality::missed;
        account(l, next_li, r, "recorder fell behind: tick not polled in time");
      }
      lock.unlock();
      LoopValues v;
      try {
        v = w.bus->read(l.bus_index);
      } catch (const std::exception& e) {  // drivers report by quality; this is a last guard
        v.error = std::string("driver failure: ") + e.what();
      }
      lock.lock();
      SampleRow r;
      r.loop_id = static_cast<std::int64_t>(next_li);
      r.tick = k_now;
      r.wall = wall_now();
      // Lateness against the tick that was due, so that falling behind shows in the figures.
      r.lateness = since(t0, start) - static_cast<double>(l.next_tick) * P;
      r.values = v.points;
      lateness.push_back(r.lateness);
      lateness_max = std::max(lateness_max, r.lateness);
      account(l, next_li, r, v.error);
      l.next_tick = k_now + 1;
    }
  }

  RecorderStatus status(double elapsed) {
    std::lock_guard lock(mutex);
    RecorderStatus s;
    s.run = run;
    s.elapsed_s = elapsed;
    s.rows = rows;
    s.committed = committed;
    s.bad_rows = bad_rows;
    s.missed = missed;
    s.lateness_p50_s = lateness.empty() ? 0.0 : quantile(lateness, 0.5);  // none yet: 0
    s.lateness_p99_s = lateness.empty() ? 0.0 : quantile(lateness, 0.99);
    s.lateness_max_s = lateness_max;
    s.loops = counts;
    s.last_error = last_error;
    if (busy_since) {
      s.busy_s = since(*busy_since, Clock::now());
      s.waiting = rows - committed;
    }
    s.waiting_peak = std::max<std::uint64_t>(waiting_peak, s.waiting);
    s.busy_longest_s = std::max(busy_longest, s.busy_s);
    s.busy_times = busy_times;
    s.busy_message = busy_message;
    for (const auto& w : workers) s.buses.emplace_back(w.bus->name(), w.bus->stats());
    return s;
  }

  // Runs `write`; true when it was stored. A busy database (another process holding the write
  // lock) returns false while it has been busy less than busy_limit_s, and throws after.
  bool stored(const std::function<void()>& write, Clock::time_point now) {
    try {
      write();
    } catch (const DatabaseBusyError& e) {
      std::lock_guard lock(mutex);
      if (!busy_since) {
        busy_since = now;
        ++busy_times;
      }
      busy_message = e.what();
      waiting_peak = std::max<std::uint64_t>(waiting_peak, rows - committed);
      if (since(*busy_since, now) <= opt.busy_limit_s) return false;
      char b[160];
      std::snprintf(b, sizeof b,
                    "; still busy after %.0f s (the recorder waits up to %.0f s): stopped, %llu "
                    "sample(s) held in memory not stored",
                    since(*busy_since, now), opt.busy_limit_s,
                    static_cast<unsigned long long>(rows - committed));
      throw std::runtime_error(busy_message + b);
    }
    std::lock_guard lock(mutex);
    if (busy_since) busy_longest = std::max(busy_longest, since(*busy_since, now));
    busy_since.reset();
    return true;
  }

  // What the database needs before the first row, each step once: the tables, the runs a
  // killed recorder left, the run, the loops. Throws DatabaseBusyError while it is busy.
  void set_up() {
    if (!db->tables_open()) db->open_tables();
    if (!interrupted_marked) {
      interrupted = db->mark_interrupted_runs();
      interrupted_marked = true;
    }
    if (run == 0) {
      const std::int64_t r = db->begin_run(site.file, started_utc);
      {
        std::lock_guard lock(mutex);  // status() reads it from other threads
        run = r;
      }
      db_lock->set_run(run);
    }
    for (auto& l : loops)
      if (l.db_id == 0) l.db_id = db->add_loop(run, l.cfg);
    ready = true;
  }

  // Stores the rows and gaps produced so far; false while the database is busy (they wait).
  bool commit(Clock::time_point now) {
    {
      std::lock_guard lock(mutex);
      if (pending.empty())
        pending.swap(queue);  // the usual case: nothing waiting
      else
        pending.insert(pending.end(), queue.begin(), queue.end());
      queue.clear();
      pending_gaps.insert(pending_gaps.end(), closed_gaps.begin(), closed_gaps.end());
      closed_gaps.clear();
    }
    if (!ready && !stored([&] { set_up(); }, now)) return false;
    for (; mapped < pending.size(); ++mapped)
      pending[mapped].loop_id = loops[static_cast<std::size_t>(pending[mapped].loop_id)].db_id;
    for (; mapped_gaps < pending_gaps.size(); ++mapped_gaps)
      pending_gaps[mapped_gaps].loop_id =
          loops[static_cast<std::size_t>(pending_gaps[mapped_gaps].loop_id)].db_id;
    if (!stored([&] { db->insert(pending, pending_gaps); }, now)) return false;
    std::lock_guard lock(mutex);
    committed += pending.size();
    pending.clear();
    pending_gaps.clear();
    mapped = mapped_gaps = 0;
    return true;
  }
};

Recorder::Recorder(SiteConfig site, RecorderOptions options, BusFactory factory)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.site = std::move(site);
  m.opt = std::move(options);
  m.factory = std::move(factory);
  for (const auto& name : m.opt.loops)
    if (!m.site.find_loop(name)) {
      std::string known;
      for (const auto& l : m.site.loops) known += (known.empty() ? "" : ", ") + l.name;
      throw std::invalid_argument("--loops: no loop '" + name + "' in " + m.site.file +
                                  " (loops: " + known + ")");
    }
  if (m.opt.duration_s && !(*m.opt.duration_s > 0))
    throw std::invalid_argument("the duration must be positive");
  for (const auto& l : m.site.loops) {
    if (!m.opt.loops.empty() &&
        std::find(m.opt.loops.begin(), m.opt.loops.end(), l.name) == m.opt.loops.end())
      continue;
    PolledLoop p;
    p.cfg = l;
    if (m.opt.duration_s)
      p.end_tick =
          static_cast<std::int64_t>(std::ceil(*m.opt.duration_s / l.sample_period_s - 1e-9));
    m.loops.push_back(std::move(p));
    LoopCounts c;
    c.name = l.name;
    m.counts.push_back(c);
  }
  // Buses before the database: a bus that cannot exist at all (no SocketCAN in the kernel)
  // fails before any file is created. No request is sent before run().
  for (const auto& b : m.site.buses) {
    BusWorker w;
    std::vector<LoopConfigEntry> on_bus;
    for (std::size_t i = 0; i < m.loops.size(); ++i)
      if (m.loops[i].cfg.bus == b.name) {
        m.loops[i].bus_index = on_bus.size();
        on_bus.push_back(m.loops[i].cfg);
        w.loops.push_back(i);
      }
    if (on_bus.empty()) continue;
    w.bus = m.factory(b, on_bus);
    m.workers.push_back(std::move(w));
  }
  m.db_lock = std::make_unique<RecorderLock>(m.opt.db_path);
  // A database busy now (another process's write transaction) is no reason to lose the start
  // of the recording: run() polls at once and the rows wait in memory, as mid-run.
  m.db = std::make_unique<RecordingDb>(m.opt.db_path, true, true);
  m.db->set_busy_timeout(0.25);
  try {
    // Holding the lock, no other recorder is running: a run still `recording` was cut short.
    if (m.db->tables_open()) {
      m.interrupted = m.db->mark_interrupted_runs();
      m.interrupted_marked = true;
    }
  } catch (const DatabaseBusyError&) {  // marked once the database is free
  }
}

Recorder::~Recorder() = default;

std::int64_t Recorder::run_id() const {
  return impl_->run;
}

const std::vector<std::int64_t>& Recorder::interrupted_runs() const {
  return impl_->interrupted;
}

bool Recorder::database_ready() const {
  return impl_->ready || (impl_->db->tables_open() && impl_->interrupted_marked);
}

RecorderStatus Recorder::run(const std::atomic<bool>& stop,
                             const std::function<void(const RecorderStatus&)>& on_status) {
  Impl& m = *impl_;
  m.started_utc = utc_timestamp();
  // Commits must not stall the status line: a busy database is retried each commit interval.
  m.db->set_busy_timeout(0.25);
  const auto t0 = m.opt.start.value_or(Clock::now());
  std::atomic<bool> done{false};
  std::atomic<int> running{static_cast<int>(m.workers.size())};
  // The polls first: the database's set-up below can wait (a busy timeout, a slow disk) and a
  // tick due meanwhile would be marked missed (measured: the first 5 ticks of 50 ms behind a
  // busy database). Their rows wait in memory until it is ready; the poll threads touch no
  // state set_up() writes.
  for (auto& w : m.workers)
    w.thread = std::thread([&m, &w, t0, &stop, &done, &running] {
      m.poll(w, t0, stop, done);
      --running;
    });
  // The run and its loops now if the database lets us; else the commits retry (stored() counts
  // the wait against busy_limit_s). Any other failure stops the polls before it propagates.
  try {
    (void)m.stored([&] { m.set_up(); }, Clock::now());
  } catch (...) {
    done = true;
    for (auto& w : m.workers)
      if (w.thread.joinable()) w.thread.join();
    throw;
  }
  auto last_commit = t0, last_status = t0;
  std::string failure;
  auto report = [&](Clock::time_point now) {
    if (on_status && since(last_status, now) >= m.opt.status_interval_s) {
      on_status(m.status(since(t0, now)));
      last_status = now;
    }
  };
  while (running.load() > 0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const auto now = Clock::now();
    if (since(last_commit, now) >= m.opt.commit_interval_s) {
      try {
        m.commit(now);
      } catch (const std::exception& e) {
        failure = e.what();  // a full disk, a lock held too long: stop, nothing more can be kept
        done = true;
        break;
      }
      last_commit = now;
    }
    report(now);
  }
  done = true;
  for (auto& w : m.workers)
    if (w.thread.joinable()) w.thread.join();
  {
    std::lock_guard lock(m.mutex);
    for (auto& l : m.loops)
      if (l.gap_start >= 0) {
        m.closed_gaps.push_back({static_cast<std::int64_t>(&l - m.loops.data()), l.gap_start,
                                 l.gap_last, l.gap_reason});
        ++m.counts[static_cast<std::size_t>(&l - m.loops.data())].gaps;
        l.gap_start = -1;
      }
  }
  // The rest, and the run's end, wait out a busy database as the commits did.
  const std::string end = stop.load() ? "stopped" : "completed";
  try {
    while (failure.empty() && !m.commit(Clock::now())) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      report(Clock::now());
    }
    while (failure.empty() && !m.stored([&] { m.db->end_run(m.run, end); }, Clock::now()))
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
  } catch (const std::exception& e) {
    failure = e.what();
  }
  const RecorderStatus s = m.status(since(t0, Clock::now()));
  if (!failure.empty()) {
    try {
      if (m.run > 0) m.db->end_run(m.run, "interrupted");
    } catch (const std::exception&) {  // busy or failing: the next recorder marks it
    }
    throw std::runtime_error(failure);
  }
  return s;
}

}  // namespace valvediag
