// valvediag import: loops of a MATLAB .mat file listed, written as CSV, or stored in a recording
// database as a recorded loop.
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>

#include "commands.hpp"
#include "isolated_mat_reader.hpp"
#include "valvediag/io/csv_writer.hpp"
#include "valvediag/io/data_error.hpp"
#include "valvediag/io/mat_reader.hpp"
#include "valvediag/recorder/recorder.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag::cli {
namespace {

struct ImportArgs {
  std::string file, loop, out, out_dir, db, name;
  std::string op = "op", pv = "pv", sp, mv, t, sample_period;
};

// A file or loop name made of the path: "benchmark.chemicals.loop23", "runs(2)" -> "runs_2".
std::string plain_name(const std::string& path, const std::string& file) {
  if (path == ".") return std::filesystem::path(file).stem().string();
  std::string s;
  for (char c : path) {
    if (std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '_')
      s += c;
    else if (c == '(' || c == '{')
      s += '_';
  }
  return s.empty() ? "loop" : s;
}

std::string seconds(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

void list(const ImportArgs& a) {
  const MatFileInfo info = list_mat_loops_isolated(a.file);
  std::size_t loops = 0, matrices = 0, with_pv = 0;
  std::map<std::string, std::size_t> groups;  // parent path -> loops
  std::vector<std::string> order;
  std::size_t width = 4;
  for (const auto& l : info.loops) {
    (l.matrix ? matrices : loops)++;
    with_pv += l.has_pv;
    width = std::max(width, l.path.size());
    const auto dot = l.path.rfind('.');
    const std::string parent =
        dot == std::string::npos || l.path == "." ? "" : l.path.substr(0, dot);
    if (!l.matrix && !parent.empty() && groups[parent]++ == 0) order.push_back(parent);
  }
  std::cout << a.file << " (" << info.format << "): " << loops << " loop(s)";
  if (matrices) std::cout << ", " << matrices << " matrix(es)";
  std::cout << "\n";
  if (info.loops.empty()) {
    std::cout << "no loop: no struct with an OP field and no numeric matrix\n";
    return;
  }
  if (order.size() > 1) {
    std::cout << "groups:";
    for (std::size_t i = 0; i < order.size(); ++i)
      std::cout << (i ? ", " : " ") << order[i] << " " << groups[order[i]];
    std::cout << "\n";
  }
  std::cout << "  " << std::left << std::setw(static_cast<int>(width)) << "loop" << std::right
            << std::setw(9) << "samples" << std::setw(9) << "Ts (s)"
            << "  signals\n";
  for (const auto& l : info.loops) {
    std::cout << "  " << std::left << std::setw(static_cast<int>(width)) << l.path << std::right
              << std::setw(9) << l.samples << std::setw(9)
              << (l.ts ? seconds(*l.ts) : std::string("-")) << "  ";
    if (l.matrix) {
      std::cout << "matrix, " << l.columns
                << " columns (name them: --op N --pv N --sample-period S)";
    } else {
      std::string s;
      for (auto [has, n] :
           {std::pair{l.has_op, "OP"}, {l.has_pv, "PV"}, {l.has_sp, "SP"}, {l.has_mv, "MV"}})
        if (has) s += (s.empty() ? "" : " ") + std::string(n);
      if (!l.has_pv) s += "  (no PV)";
      if (!l.ts) s += "  (no Ts)";
      for (const auto& [name, value] : l.scalars)  // a database's labels (`oscillation`)
        s += "  " + name + " " + strprintf("%g", value);
      std::cout << s;
    }
    std::cout << "\n";
  }
  if (loops > 0 && with_pv == 0)
    std::cout << "no loop has PV: fit and diagnose need OP and PV; import writes t, op (and sp) "
                 "only\n";
  std::cout << "import one: valvediag import " << a.file << " --loop " << info.loops.front().path
            << (info.loops.front().matrix ? " --op N --pv N --sample-period S" : "")
            << " --out loop.csv   (or --db site.sqlite)\n";
}

MatOptions mat_options(const ImportArgs& a, bool require_pv) {
  MatOptions m;
  m.op = a.op;
  m.pv = a.pv;
  m.sp = a.sp;
  m.mv = a.mv;
  m.t = a.t;
  m.require_pv = require_pv;
  if (!a.sample_period.empty()) {
    try {
      std::size_t pos = 0;
      m.sample_period = std::stod(a.sample_period, &pos);
      if (pos != a.sample_period.size()) throw std::invalid_argument("trailing text");
    } catch (const std::exception&) {
      throw UsageError("--sample-period must be a number of seconds, got '" + a.sample_period +
                       "'");
    }
  }
  return m;
}

// Writes t, op, pv (and sp, mv); a loop without PV as t, op (and sp, mv).
void write_csv(const std::string& out, const LoopData& d) {
  if (d.has_pv()) {
    write_loop_csv(out, d);
    return;
  }
  std::vector<std::string> names{"t", "op"};
  std::vector<std::vector<double>> cols{d.t, d.op};
  if (d.has_sp()) {
    names.push_back("sp");
    cols.push_back(d.sp);
  }
  if (d.has_mv()) {
    names.push_back("mv");
    cols.push_back(d.mv);
  }
  write_columns_csv(out, names, cols);
}

std::string wrote(const std::string& out, const LoopData& d, const std::string& path) {
  std::string s = "wrote " + out + ": " + std::to_string(d.size()) + " samples of loop " + path +
                  " (Ts " + seconds(d.sample_period()) + " s)";
  if (!d.has_pv()) s += "; no PV in the file: t, op only (fit and diagnose need a pv column)";
  return s;
}

// The loop as one run of a recording, every sample good: `fit --db DB --loop NAME` reads it.
std::int64_t store(const std::string& db_path, const std::string& name, const LoopData& d,
                   const std::string& source) {
  RecordingDb db(db_path, true);
  const std::int64_t run = db.begin_run(source);
  LoopConfigEntry e;
  e.name = name;
  e.bus = "import";
  e.sample_period_s = d.sample_period();
  e.points[static_cast<std::size_t>(PointName::op)].present = true;
  e.points[static_cast<std::size_t>(PointName::pv)].present = true;
  e.points[static_cast<std::size_t>(PointName::sp)].present = d.has_sp();
  e.points[static_cast<std::size_t>(PointName::mv)].present = d.has_mv();
  const std::int64_t id = db.add_loop(run, e);
  std::vector<SampleRow> rows;
  const double P = d.sample_period();
  auto point = [](const std::vector<double>& v, std::size_t i) {
    return v.empty() ? PointValue{} : PointValue{v[i], Quality::good};
  };
  for (std::size_t i = 0; i < d.size(); ++i) {
    SampleRow r;
    r.loop_id = id;
    r.tick = std::llround((d.t[i] - d.t[0]) / P);
    r.wall = d.t[i] - d.t[0];  // no clock time in the file: seconds from the first sample
    r.values[static_cast<std::size_t>(PointName::op)] = point(d.op, i);
    r.values[static_cast<std::size_t>(PointName::pv)] = point(d.pv, i);
    r.values[static_cast<std::size_t>(PointName::sp)] = point(d.sp, i);
    r.values[static_cast<std::size_t>(PointName::mv)] = point(d.mv, i);
    rows.push_back(r);
    if (rows.size() == 10000) {
      db.insert(rows);
      rows.clear();
    }
  }
  db.insert(rows);
  db.end_run(run, "imported");
  return run;
}

}  // namespace

void add_import(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "import",
      "List the loops of a MATLAB .mat file; write one (or all) as CSV or into a "
      "recording");
  cmd->footer(
      "Examples:\n"
      "  valvediag import benchmark.mat                        # list the loops\n"
      "  valvediag import benchmark.mat --loop chemicals.loop23 --out loop23.csv\n"
      "  valvediag import benchmark.mat --out-dir loops/       # every loop, one CSV each\n"
      "  valvediag import runs.mat --loop 'runs(2)' --db site.sqlite && valvediag fit --db "
      "site.sqlite --loop runs_2\n"
      "  valvediag import m1d14.mat --loop m1d14 --op 51 --pv 21 --sample-period 36 --out te.csv\n"
      "A loop is a struct with an OP field (any case) and Ts, usually PV, optionally SP and MV, "
      "anywhere in the file\n(structs, struct arrays 'runs(2)', cells 'c{3}'); its path may leave "
      "out leading parts when the rest is unique.\nA plain matrix holds samples in rows: name its "
      "columns by 1-based number and give the sample period.\nfit, diagnose and report read the "
      "same: valvediag fit FILE.mat --loop PATH [--op N --pv N --sample-period S].");
  auto a = std::make_shared<ImportArgs>();
  const char* g = "Loop";
  cmd->add_option("file", a->file, "MATLAB .mat file (v5, v7 or v7.3)")->required();
  cmd->add_option("--loop", a->loop, "path of the loop in the file (as listed)")->group(g);
  cmd->add_option("--op", a->op, "OP: field of the loop struct, or 1-based column of a matrix")
      ->group(g)
      ->capture_default_str();
  cmd->add_option("--pv", a->pv, "PV: field, or column")->group(g)->capture_default_str();
  cmd->add_option("--sp", a->sp, "SP: field, or column ('none' to leave out)")->group(g);
  cmd->add_option("--mv", a->mv, "valve position: field, or column ('none' to leave out)")
      ->group(g);
  cmd->add_option("--t", a->t, "matrix only: time column (default: none, use --sample-period)")
      ->group(g);
  cmd->add_option("--sample-period", a->sample_period,
                  "s: for a matrix without time column or a loop without Ts")
      ->group(g);
  const char* o = "Output";
  auto* out =
      cmd->add_option("--out", a->out, "CSV file for the loop (t, op, pv, sp, mv)")->group(o);
  cmd->add_option("--out-dir", a->out_dir, "write the loop, or every loop, as DIR/PATH.csv")
      ->group(o)
      ->excludes(out);
  cmd->add_option("--db", a->db, "store the loop in this recording (created if missing)")->group(o);
  cmd->add_option("--name", a->name,
                  "with --db: the loop's name there (default: its path, runs(2) as runs_2)")
      ->group(o);
  cmd->callback([a, &exit_code] {
    if (!is_mat_file(a->file))
      throw UsageError(a->file +
                       ": import reads MATLAB .mat files (CSV files are read directly "
                       "by fit and diagnose)");
    if (!a->name.empty() && a->db.empty()) throw UsageError("--name goes with --db");
    exit_code = kOk;
    if (a->out.empty() && a->out_dir.empty() && a->db.empty()) {
      if (!a->loop.empty())
        throw UsageError("say where the loop goes: --out FILE.csv, --out-dir DIR or --db FILE");
      list(*a);
      return;
    }
    std::vector<std::string> notes;
    if (!a->out_dir.empty() && a->loop.empty() && a->db.empty()) {
      // Every loop: those that cannot be read as they are (a matrix without columns, no Ts)
      // are named and skipped.
      std::filesystem::create_directories(a->out_dir);
      std::size_t written = 0, skipped = 0;
      for (const auto& l : list_mat_loops_isolated(a->file).loops) {
        const std::string out =
            (std::filesystem::path(a->out_dir) / (plain_name(l.path, a->file) + ".csv")).string();
        try {
          const LoopData d = read_mat_loop_isolated(a->file, l.path, mat_options(*a, false));
          write_csv(out, d);
          std::cout << wrote(out, d, l.path) << "\n";
          ++written;
        } catch (const DataError& e) {
          std::cout << "skipped " << l.path << ": " << e.what() << "\n";
          ++skipped;
        }
      }
      std::cout << written << " loop(s) written to " << a->out_dir;
      if (skipped) std::cout << ", " << skipped << " skipped";
      std::cout << "\n";
      if (written == 0) exit_code = kBadInput;
      return;
    }
    // One loop: --loop, or the file's only loop.
    const bool to_db = !a->db.empty();
    LoopData d = read_mat_loop_isolated(a->file, a->loop, mat_options(*a, to_db), &notes);
    for (const auto& n : notes) std::cout << "note: " << n << "\n";
    const std::string path = d.source.substr(a->file.size() + 1);  // "FILE:PATH"
    if (!a->out.empty() || !a->out_dir.empty()) {
      const std::string out =
          !a->out.empty()
              ? a->out
              : (std::filesystem::create_directories(a->out_dir),
                 (std::filesystem::path(a->out_dir) / (plain_name(path, a->file) + ".csv"))
                     .string());
      write_csv(out, d);
      std::cout << wrote(out, d, path) << "\n";
    }
    if (to_db) {
      const std::string name = a->name.empty() ? plain_name(path, a->file) : a->name;
      const std::int64_t run = store(a->db, name, d, "import " + a->file + " " + path);
      std::cout << "stored loop " << name << " in " << a->db << " (run " << run << ", " << d.size()
                << " samples, Ts " << seconds(d.sample_period()) << " s): valvediag fit --db "
                << a->db << " --loop " << name << "\n";
    }
  });
}

}  // namespace valvediag::cli
