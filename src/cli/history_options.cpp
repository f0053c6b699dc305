#include "history_options.hpp"

#include <algorithm>
#include <cstdio>
#include <iostream>

namespace valvediag::cli {

void add_history_options(CLI::App* cmd, HistoryOptions& h, const char* group, bool writes) {
  cmd->add_option("--history", h.file,
                  "the model history file (default: one per data content and reading options in "
                  "$XDG_STATE_HOME/valvediag, else ~/.local/state/valvediag; for --db, the "
                  "recording's table model_history)")
      ->group(group);
  if (writes) cmd->add_flag("--no-history", h.off, "do not add to the model history")->group(group);
}

std::string reading_options(const DataOptions& d) {
  const CsvOptions& c = d.csv;
  std::string s;
  for (const std::string& v :
       {c.t_column, c.op_column, c.pv_column, c.sp_column, c.mv_column, c.delimiter,
        std::to_string(c.skip_lines), std::to_string(c.skip_after_header), c.time_format,
        std::string(c.resample ? "resample" : ""), d.sample_period, d.decimal, d.loop, d.from,
        d.to})
    s += v + '\x1f';  // a separator no option holds: "a,b" + "c" is not "a" + "b,c"
  return s;
}

namespace {

// --from/--to as numbers ("600" and "600.0" read the same samples): the recording's key.
std::string db_reading(const DataOptions& d) {
  std::string s;
  for (const auto& [opt, v] : {std::pair{"--from", &d.from}, std::pair{"--to", &d.to}}) {
    if (v->empty()) continue;
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.15g", std::stod(*v));  // load_data checked it
    s += (s.empty() ? "" : " ") + std::string(opt) + " " + buf;
  }
  // Interpolated samples are other data than a reading without them.
  if (d.bridge_gaps > 0)
    s += (s.empty() ? "" : " ") + std::string("--bridge-gaps ") + std::to_string(d.bridge_gaps);
  return s;
}

}  // namespace

std::string HistoryPlace::where() const {
  return db.empty() ? file : db + " (table model_history)";
}

HistoryPlace history_place(const HistoryOptions& h, const DataOptions& d, const LoopData& data) {
  HistoryPlace p;
  if (!h.file.empty()) {
    p.file = h.file;
    return p;
  }
  std::string why;
  const std::string dir = history_state_dir(why);
  if (!d.db.empty()) {
    // A recorded loop's history lives in its recording; the state directory only catches what
    // the database cannot take.
    p.db = d.db;
    p.key = {d.run_read, d.loop, db_reading(d)};
  } else if (dir.empty() && !h.off) {
    std::cerr << "warning: " << why << "; going on without a model history\n";
  }
  if (!dir.empty()) p.file = history_file_in(dir, history_key(data, reading_options(d)));
  return p;
}

std::vector<HistoryEntry> load_history_at(const HistoryPlace& p) {
  std::vector<HistoryEntry> out;
  if (!p.db.empty())
    for (const std::string& text : load_recording_history(p.db, p.key))
      out.push_back(history_entry_from_json(text, p.where()));
  if (p.file.empty()) return out;
  std::vector<HistoryEntry> more = load_history(p.file);
  if (p.db.empty() || more.empty()) return more.empty() ? out : more;
  // Entries the database could not take: in time order with the others (UTC ISO 8601 sorts).
  out.insert(out.end(), more.begin(), more.end());
  std::stable_sort(out.begin(), out.end(),
                   [](const HistoryEntry& a, const HistoryEntry& b) { return a.time < b.time; });
  return out;
}

std::vector<HistoryEntry> read_history_or_warn(HistoryPlace& p) {
  if (p.empty()) return {};
  try {
    return load_history_at(p);
  } catch (const std::runtime_error& e) {
    std::cerr << "warning: " << e.what() << "; going on without it\n";
    p = {};
    return {};
  }
}

namespace {

// "model history: PATH (3 fits)", "model history: site.sqlite (table model_history, 3 fits)".
void say_where(const std::string& where, const std::string& table, std::size_t total) {
  std::cout << "model history: " << where << " (" << table << total
            << (total == 1 ? " fit)" : " fits)") << "\n";
}

}  // namespace

HistoryAppended append_history_at(const HistoryPlace& p, const std::vector<HistoryEntry>& entries) {
  HistoryAppended out;
  if (p.empty() || entries.empty()) return out;
  if (!p.db.empty()) {
    std::vector<StoredHistoryEntry> rows;
    for (const HistoryEntry& e : entries)
      rows.push_back({e.model, e.time, history_entry_to_json(e)});
    try {
      out.total = append_recording_history(p.db, p.key, rows);
      out.where = p.where();
      return out;
    } catch (const std::exception& e) {
      if (p.file.empty()) {
        out.error = e.what();
        return out;
      }
      out.warnings.push_back(e.what());
    }
  }
  std::string why;
  if (try_append_history(p.file, entries, why, &out.total))
    out.where = p.file;
  else
    out.error = why;
  return out;
}

void record_history(const HistoryPlace& p, const std::vector<HistoryEntry>& entries,
                    const std::string& result) {
  const char* elsewhere = " (--no-history skips this, --history FILE puts it elsewhere)\n";
  const HistoryAppended r = append_history_at(p, entries);
  for (const auto& w : r.warnings)
    std::cerr << "warning: " << w << "; the model history goes to the state directory instead\n";
  if (!r.error.empty())
    std::cerr << "warning: " << r.error << "; " << result
              << (p.db.empty() || !p.file.empty() ? " stands" : " stands without a model history")
              << elsewhere;
  else if (!r.where.empty())
    say_where(r.where == p.file ? p.file : p.db, r.where == p.file ? "" : "table model_history, ",
              r.total);
}

}  // namespace valvediag::cli
