#include "history_options.hpp"

#include <iostream>

namespace valvediag::cli {

void add_history_options(CLI::App* cmd, HistoryOptions& h, const char* group, bool writes) {
  cmd->add_option("--history", h.file,
                  "the model history file (default: one per data content and reading options in "
                  "$XDG_STATE_HOME/valvediag, else ~/.local/state/valvediag)")
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

std::string history_file(const HistoryOptions& h, const DataOptions& d, const LoopData& data) {
  if (!h.file.empty()) return h.file;
  std::string why;
  const std::string dir = history_state_dir(why);
  if (dir.empty()) {
    if (!h.off) std::cerr << "warning: " << why << "; going on without a model history\n";
    return "";
  }
  return history_file_in(dir, history_key(data, reading_options(d)));
}

std::vector<HistoryEntry> read_history_or_warn(std::string& path) {
  if (path.empty()) return {};
  try {
    return load_history(path);
  } catch (const std::runtime_error& e) {
    std::cerr << "warning: " << e.what() << "; going on without it\n";
    path.clear();
    return {};
  }
}

void record_history(const std::string& path, const std::vector<HistoryEntry>& entries,
                    const std::string& result) {
  if (path.empty() || entries.empty()) return;
  std::string why;
  std::size_t total = 0;
  if (try_append_history(path, entries, why, &total))
    std::cout << "model history: " << path << " (" << total << (total == 1 ? " fit)" : " fits)")
              << "\n";
  else
    std::cerr << "warning: " << why << "; " << result
              << " stands (--no-history skips this, --history FILE puts it elsewhere)\n";
}

}  // namespace valvediag::cli
