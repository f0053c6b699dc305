#include "isolated_mat_reader.hpp"

#include <csignal>
#include <cstdint>
#include <cstring>
#include <functional>
#include <optional>
#include <stdexcept>
#include <utility>

#include "isolated_jobs.hpp"
#include "valvediag/io/data_error.hpp"

namespace valvediag::cli {

namespace {

// The child's reply: 'R' + the result, or 'D' + a DataError's fields. Plain bytes: the doubles
// cross unchanged (NaN included), which text would not promise.
class Writer {
 public:
  std::string out;
  void u64(std::uint64_t v) { out.append(reinterpret_cast<const char*>(&v), sizeof v); }
  void f64(double v) { out.append(reinterpret_cast<const char*>(&v), sizeof v); }
  void str(const std::string& s) {
    u64(s.size());
    out.append(s);
  }
  void doubles(const std::vector<double>& v) {
    u64(v.size());
    out.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(double));
  }
  void strings(const std::vector<std::string>& v) {
    u64(v.size());
    for (const auto& s : v) str(s);
  }
};

class Reader {
 public:
  // Reads s from byte `from` on (past the reply's tag).
  Reader(const std::string& s, std::size_t from) : s_(s), pos_(from) {}
  std::uint64_t u64() {
    std::uint64_t v;
    std::memcpy(&v, take(sizeof v), sizeof v);
    return v;
  }
  double f64() {
    double v;
    std::memcpy(&v, take(sizeof v), sizeof v);
    return v;
  }
  std::string str() {
    const std::size_t n = count(1);
    return std::string(take(n), n);
  }
  std::vector<double> doubles() {
    const std::size_t n = count(sizeof(double));
    std::vector<double> v(n);
    if (n) std::memcpy(v.data(), take(n * sizeof(double)), n * sizeof(double));
    return v;
  }
  std::vector<std::string> strings() {
    std::vector<std::string> v(count(sizeof(std::uint64_t)));
    for (auto& s : v) s = str();
    return v;
  }

 private:
  // A length that cannot exceed what is left (a garbled reply must not allocate wildly).
  std::size_t count(std::size_t unit) {
    const std::uint64_t n = u64();
    if (n > (s_.size() - pos_) / unit) throw std::runtime_error("malformed reply");
    return static_cast<std::size_t>(n);
  }
  const char* take(std::size_t n) {
    if (n > s_.size() - pos_) throw std::runtime_error("malformed reply");
    const char* p = s_.data() + pos_;
    pos_ += n;
    return p;
  }
  const std::string& s_;
  std::size_t pos_;
};

// Runs read() in a child; returns its reply ('R' + the result bytes) or throws what the child
// threw.
std::string in_child(const std::string& path, double timeout_s,
                     const std::function<std::string()>& read) {
  JobOutcome outcome;
  run_isolated(
      1, 1, timeout_s,
      [&](std::size_t) {
        // append() only: g++ 12 reports a false -Wrestrict on "literal" + std::string.
        std::string reply(1, 'R');
        // A crash in libmatio ends the child at once, whatever handler the process installed.
        for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL}) std::signal(sig, SIG_DFL);
        try {
          return reply.append(read());
        } catch (const DataError& e) {
          Writer w;
          w.str(e.file);
          w.u64(e.line);
          w.str(e.column);
          w.str(e.what());
          return reply.assign(1, 'D').append(w.out);
        }
      },
      [&](std::size_t, const JobOutcome& o) { outcome = o; });
  const std::string advice =
      ": the file is damaged or in a form libmatio cannot read; check that it opens in MATLAB or "
      "Octave and save it again (save -v7), or export the loop as CSV";
  switch (outcome.status) {
    case JobOutcome::Status::Ok:
      break;
    case JobOutcome::Status::Failed:  // not a DataError: e.g. out of memory on absurd sizes
      throw DataError(
          path, 0, "",
          std::string("reading it failed (").append(outcome.message).append(")").append(advice));
    case JobOutcome::Status::TimedOut:
      throw DataError(path, 0, "",
                      std::string("reading it did not finish within ")
                          .append(std::to_string(static_cast<int>(timeout_s)))
                          .append(" s")
                          .append(advice));
    case JobOutcome::Status::Crashed:
      throw DataError(path, 0, "",
                      (outcome.signal ? std::string("libmatio crashed reading it (signal ")
                                            .append(std::to_string(outcome.signal))
                                            .append(", ")
                                            .append(strsignal(outcome.signal))
                                            .append(")")
                                      : std::string("reading it ended without a result")) +
                          advice);
    case JobOutcome::Status::Cancelled:
      throw std::runtime_error(path + ": reading was cancelled");
  }
  std::string& r = outcome.output;
  if (!r.empty() && r[0] == 'R') return std::move(r);
  if (!r.empty() && r[0] == 'D') {
    Reader in(r, 1);
    std::string file = in.str();
    const std::size_t line = in.u64();
    std::string column = in.str();
    throw DataError::rebuilt(std::move(file), line, std::move(column), in.str());
  }
  throw std::runtime_error(path + ": the reading process sent no result");
}

}  // namespace

MatFileInfo list_mat_loops_isolated(const std::string& path, double timeout_s) {
  const std::string bytes = in_child(path, timeout_s, [&] {
    const MatFileInfo info = list_mat_loops(path);
    Writer w;
    w.str(info.format);
    w.u64(info.loops.size());
    for (const auto& l : info.loops) {
      w.str(l.path);
      w.u64(l.matrix);
      w.u64(l.samples);
      w.u64(l.columns);
      w.u64(l.ts.has_value());
      w.f64(l.ts.value_or(0.0));
      w.u64((l.has_op ? 1u : 0u) | (l.has_pv ? 2u : 0u) | (l.has_sp ? 4u : 0u) |
            (l.has_mv ? 8u : 0u));
      w.strings(l.fields);
      w.u64(l.scalars.size());
      for (const auto& [name, value] : l.scalars) {
        w.str(name);
        w.f64(value);
      }
    }
    return w.out;
  });
  Reader in(bytes, 1);
  MatFileInfo info;
  info.format = in.str();
  const std::uint64_t n = in.u64();
  for (std::uint64_t i = 0; i < n; ++i) {
    MatLoopInfo l;
    l.path = in.str();
    l.matrix = in.u64() != 0;
    l.samples = in.u64();
    l.columns = in.u64();
    const bool has_ts = in.u64() != 0;
    const double ts = in.f64();
    if (has_ts) l.ts = ts;
    const std::uint64_t flags = in.u64();
    l.has_op = flags & 1u;
    l.has_pv = flags & 2u;
    l.has_sp = flags & 4u;
    l.has_mv = flags & 8u;
    l.fields = in.strings();
    const std::uint64_t scalars = in.u64();
    for (std::uint64_t k = 0; k < scalars; ++k) {
      std::string name = in.str();
      l.scalars.emplace_back(std::move(name), in.f64());
    }
    info.loops.push_back(std::move(l));
  }
  return info;
}

LoopData read_mat_loop_isolated(const std::string& path, const std::string& loop,
                                const MatOptions& options, std::vector<std::string>* notes,
                                double timeout_s) {
  const std::string bytes = in_child(path, timeout_s, [&] {
    std::vector<std::string> child_notes;
    const LoopData d = read_mat_loop(path, loop, options, &child_notes);
    Writer w;
    for (const auto* v : {&d.t, &d.op, &d.pv, &d.sp, &d.mv}) w.doubles(*v);
    w.str(d.source);
    w.strings(child_notes);
    return w.out;
  });
  Reader in(bytes, 1);
  LoopData d;
  for (auto* v : {&d.t, &d.op, &d.pv, &d.sp, &d.mv}) *v = in.doubles();
  d.source = in.str();
  const auto child_notes = in.strings();
  if (notes) notes->insert(notes->end(), child_notes.begin(), child_notes.end());
  return d;
}

}  // namespace valvediag::cli
