// MAT-file loops through libmatio. The file's header and top-level element tags are checked here
// before libmatio reads anything, so a truncated or foreign file gets a clear DataError instead of
// whatever libmatio would make of it; libmatio's log messages are captured, never printed.
#include "valvediag/io/mat_reader.hpp"

#include <matio.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <mutex>
#include <string_view>

#include "valvediag/io/data_checks.hpp"
#include "valvediag/io/data_error.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag {
namespace {

// libmatio's messages for the current call on this thread.
thread_local std::string* g_log = nullptr;

void capture_log(int level, char* message) {
  if (g_log == nullptr || message == nullptr) return;
  if (level & (MATIO_LOG_LEVEL_ERROR | MATIO_LOG_LEVEL_CRITICAL | MATIO_LOG_LEVEL_WARNING)) {
    if (!g_log->empty()) g_log->append("; ");
    g_log->append(message);
  }
}

// Routes libmatio's log to g_log while alive (the default handler prints, and may abort on
// errors).
class LogCapture {
 public:
  LogCapture() {
    static std::once_flag once;
    std::call_once(once, [] { Mat_LogInitFunc("valvediag", capture_log); });
    previous_ = g_log;
    g_log = &text_;
  }
  ~LogCapture() { g_log = previous_; }
  LogCapture(const LogCapture&) = delete;
  LogCapture& operator=(const LogCapture&) = delete;
  const std::string& text() const { return text_; }

 private:
  std::string text_;
  std::string* previous_ = nullptr;
};

struct MatCloser {
  void operator()(mat_t* m) const { Mat_Close(m); }
};
struct VarFreer {
  void operator()(matvar_t* v) const { Mat_VarFree(v); }
};
using MatPtr = std::unique_ptr<mat_t, MatCloser>;
using VarPtr = std::unique_ptr<matvar_t, VarFreer>;

std::string lower(std::string_view s) {
  std::string o(s);
  for (char& c : o) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return o;
}

// A name from the file, safe to print: anything but printable ASCII becomes '?'.
std::string printable(const char* s) {
  std::string o = s ? s : "";
  for (char& c : o)
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7e) c = '?';
  return o;
}

// Number of elements, 0 on overflow or a bad rank.
std::size_t element_count(const matvar_t* v) {
  if (v == nullptr || v->rank < 0 || v->rank > 32 || (v->rank > 0 && v->dims == nullptr)) return 0;
  std::size_t n = 1;
  for (int i = 0; i < v->rank; ++i) {
    const std::size_t d = v->dims[i];
    if (d != 0 && n > SIZE_MAX / d) return 0;
    n *= d;
  }
  return n;
}

std::string dims_text(const matvar_t* v) {
  std::string s;
  for (int i = 0; v->dims && i < v->rank && i < 32; ++i)
    s += (i ? " x " : "") + std::to_string(v->dims[i]);
  return s;
}

bool is_numeric_class(matio_classes c) {
  return c == MAT_C_DOUBLE || c == MAT_C_SINGLE || (c >= MAT_C_INT8 && c <= MAT_C_UINT64);
}

std::size_t class_size(matio_classes c) {
  switch (c) {
    case MAT_C_DOUBLE:
    case MAT_C_INT64:
    case MAT_C_UINT64:
      return 8;
    case MAT_C_SINGLE:
    case MAT_C_INT32:
    case MAT_C_UINT32:
      return 4;
    case MAT_C_INT16:
    case MAT_C_UINT16:
    case MAT_C_CHAR:
      return 2;
    default:
      return 1;
  }
}

// What a variable is, for messages: "double 1500 x 1", "struct 1 x 1".
std::string describe(const matvar_t* v) {
  static const char* const names[] = {"empty",  "cell",   "struct", "object", "char",     "sparse",
                                      "double", "single", "int8",   "uint8",  "int16",    "uint16",
                                      "int32",  "uint32", "int64",  "uint64", "function", "opaque"};
  const auto c = static_cast<std::size_t>(v->class_type);
  std::string s = c < std::size(names) ? names[c] : "unknown";
  if (v->isComplex) s = "complex " + s;
  return s + " " + dims_text(v);
}

bool is_vector(const matvar_t* v) {
  if (v->rank != 2 || v->dims == nullptr) return false;
  return v->dims[0] == 1 || v->dims[1] == 1;
}

bool is_real_numeric(const matvar_t* v) {
  return v != nullptr && is_numeric_class(v->class_type) && !v->isComplex;
}

// The values of a real numeric variable as doubles (column-major), or an empty optional with the
// reason.
std::optional<std::vector<double>> values(const matvar_t* v, std::string& why) {
  if (v == nullptr) {
    why = "unreadable";
    return std::nullopt;
  }
  if (!is_numeric_class(v->class_type)) {
    why = "is " + describe(v) + ", not numeric";
    return std::nullopt;
  }
  if (v->isComplex) {
    why = "is complex";
    return std::nullopt;
  }
  const std::size_t n = element_count(v);
  if (n == 0) {
    why = "is empty";
    return std::nullopt;
  }
  std::size_t size = 0;
  switch (v->data_type) {
    case MAT_T_DOUBLE:
    case MAT_T_INT64:
    case MAT_T_UINT64:
      size = 8;
      break;
    case MAT_T_SINGLE:
    case MAT_T_INT32:
    case MAT_T_UINT32:
      size = 4;
      break;
    case MAT_T_INT16:
    case MAT_T_UINT16:
      size = 2;
      break;
    case MAT_T_INT8:
    case MAT_T_UINT8:
      size = 1;
      break;
    default:
      break;
  }
  if (size == 0 || v->data == nullptr || n > SIZE_MAX / size || v->nbytes < n * size) {
    why = "holds no readable data (malformed file?)";
    return std::nullopt;
  }
  std::vector<double> out(n);
  auto copy = [&](auto tag) {
    using T = decltype(tag);
    const auto* p = static_cast<const unsigned char*>(v->data);
    for (std::size_t i = 0; i < n; ++i) {
      T x;
      std::memcpy(&x, p + i * sizeof(T), sizeof(T));
      out[i] = static_cast<double>(x);
    }
  };
  switch (v->data_type) {
    case MAT_T_DOUBLE:
      copy(double{});
      break;
    case MAT_T_SINGLE:
      copy(float{});
      break;
    case MAT_T_INT64:
      copy(std::int64_t{});
      break;
    case MAT_T_UINT64:
      copy(std::uint64_t{});
      break;
    case MAT_T_INT32:
      copy(std::int32_t{});
      break;
    case MAT_T_UINT32:
      copy(std::uint32_t{});
      break;
    case MAT_T_INT16:
      copy(std::int16_t{});
      break;
    case MAT_T_UINT16:
      copy(std::uint16_t{});
      break;
    case MAT_T_INT8:
      copy(std::int8_t{});
      break;
    default:
      copy(std::uint8_t{});
      break;
  }
  return out;
}

// ---- the file ---------------------------------------------------------------------------------

enum class Format { v5, v73 };

// Checks the 128-byte header and, for v5, that every top-level element lies inside the file;
// returns the format and, for v5, the most bytes each top-level variable can hold in memory.
Format check_file(const std::string& path, std::vector<std::uint64_t>& budgets) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw DataError(path, 0, "", "cannot open the file (does it exist? is it readable?)");
  f.seekg(0, std::ios::end);
  const auto end = f.tellg();
  if (end < 0) throw DataError(path, 0, "", "cannot read the file");
  const auto size = static_cast<std::uint64_t>(end);
  f.seekg(0);
  std::array<unsigned char, 128> h{};
  if (size < h.size() || !f.read(reinterpret_cast<char*>(h.data()), h.size()))
    throw DataError(path, 0, "",
                    "only " + std::to_string(size) +
                        " bytes: too short for a MATLAB MAT-file (truncated download?)");
  const bool text = std::string_view(reinterpret_cast<const char*>(h.data()), 6) == "MATLAB";
  const bool little = h[126] == 'I' && h[127] == 'M';
  const bool big = h[126] == 'M' && h[127] == 'I';
  if (!text || !(little || big))
    throw DataError(path, 0, "",
                    "not a MATLAB v5/v7/v7.3 MAT-file (no 'MATLAB ... MAT-file' header); a v4 "
                    "file or another format? Save it in MATLAB with save(FILE, ..., '-v7')");
  const unsigned version = little ? h[124] | (h[125] << 8) : (h[124] << 8) | h[125];
  if (version == 0x0200) return Format::v73;
  if (version != 0x0100)
    throw DataError(
        path, 0, "", "unknown MAT-file version 0x" + [&] {
          char b[8];
          std::snprintf(b, sizeof b, "%04x", version);
          return std::string(b);
        }() + " (valvediag reads v5, v7 and v7.3)");
  auto u32 = [&](const unsigned char* p) {
    return little ? std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 |
                        std::uint32_t{p[3]} << 24
                  : std::uint32_t{p[3]} | std::uint32_t{p[2]} << 8 | std::uint32_t{p[1]} << 16 |
                        std::uint32_t{p[0]} << 24;
  };
  std::uint64_t at = h.size();
  std::size_t index = 0;
  while (at < size) {
    ++index;
    std::array<unsigned char, 8> tag{};
    if (size - at < 8 || !f.seekg(static_cast<std::streamoff>(at)) ||
        !f.read(reinterpret_cast<char*>(tag.data()), tag.size()))
      throw DataError(path, 0, "",
                      "the file ends inside the header of variable " + std::to_string(index) +
                          " at byte " + std::to_string(at) + " (truncated?)");
    const std::uint32_t type = u32(tag.data()), bytes = u32(tag.data() + 4);
    if (type != MAT_T_MATRIX && type != MAT_T_COMPRESSED)
      throw DataError(path, 0, "",
                      "malformed: variable " + std::to_string(index) + " at byte " +
                          std::to_string(at) + " has element type " + std::to_string(type) +
                          " (expected a matrix or compressed element)");
    if (bytes > size - at - 8)
      throw DataError(path, 0, "",
                      "the file ends inside variable " + std::to_string(index) + " (it needs " +
                          std::to_string(bytes) + " bytes from byte " + std::to_string(at + 8) +
                          ", the file has " + std::to_string(size - at - 8) +
                          "): truncated download or copy?");
    // zlib expands at most about 1032:1.
    budgets.push_back(type == MAT_T_COMPRESSED ? std::uint64_t{bytes} * 1100 + 65536 : bytes);
    at += 8 + std::uint64_t{bytes};
    if (type == MAT_T_MATRIX) at = std::min(size, (at + 7) / 8 * 8);
  }
  return Format::v5;
}

// Bytes the variable's dimensions claim (saturating), from its header alone.
std::uint64_t claimed_bytes(const matvar_t* v, int depth = 0) {
  if (v == nullptr || depth > 64) return 0;
  const std::size_t n = element_count(v);
  const std::uint64_t huge = UINT64_MAX / 4;
  auto add = [&](std::uint64_t a, std::uint64_t b) { return a > huge - b ? huge : a + b; };
  if (v->class_type == MAT_C_STRUCT) {
    const unsigned nf = Mat_VarGetNumberOfFields(const_cast<matvar_t*>(v));
    std::uint64_t s = nf && n > huge / nf / 8 ? huge : std::uint64_t{n} * nf * 8;
    for (std::size_t k = 0; k < n && s < huge; ++k)
      for (unsigned i = 0; i < nf; ++i)
        s = add(s, claimed_bytes(Mat_VarGetStructFieldByIndex(const_cast<matvar_t*>(v), i, k),
                                 depth + 1));
    return s;
  }
  if (v->class_type == MAT_C_CELL) {
    std::uint64_t s = n > huge / 8 ? huge : std::uint64_t{n} * 8;
    if (v->data == nullptr) return s;
    auto* cells = static_cast<matvar_t**>(v->data);
    for (std::size_t k = 0; k < n && s < huge; ++k) s = add(s, claimed_bytes(cells[k], depth + 1));
    return s;
  }
  const std::uint64_t e = class_size(v->class_type) * (v->isComplex ? 2 : 1);
  return n > huge / e ? huge : std::uint64_t{n} * e;
}

struct File {
  std::string path;
  Format format = Format::v5;
  std::vector<VarPtr> vars;  // top-level variables, fully read
};

File open_file(const std::string& path) {
  File file;
  file.path = path;
  std::vector<std::uint64_t> budgets;
  file.format = check_file(path, budgets);
  LogCapture log;
  MatPtr mat(Mat_Open(path.c_str(), MAT_ACC_RDONLY));
  if (!mat) {
    if (file.format == Format::v73)
      throw DataError(path, 0, "",
                      "a MATLAB v7.3 (HDF5) file that libmatio cannot open" +
                          (log.text().empty() ? std::string(" (is it built without HDF5?)")
                                              : ": " + log.text()) +
                          "; save it in MATLAB with '-v7' instead");
    throw DataError(path, 0, "",
                    "libmatio cannot open it" + (log.text().empty() ? "" : ": " + log.text()));
  }
  // First the headers only: dimensions that the file cannot hold mean a malformed file, and
  // reading the data would ask for that much memory.
  std::size_t index = 0;
  while (true) {
    VarPtr info(Mat_VarReadNextInfo(mat.get()));
    if (!info) break;
    if (file.format == Format::v5 && index < budgets.size() &&
        claimed_bytes(info.get()) > budgets[index])
      throw DataError(path, 0, "",
                      "malformed: variable '" + printable(info->name) +
                          "' claims more data than the file holds");
    ++index;
    if (index > 100000) break;
  }
  if (!log.text().empty())
    throw DataError(path, 0, "", "malformed or truncated MAT-file: " + log.text());
  if (file.format == Format::v5 && index != budgets.size())
    throw DataError(path, 0, "",
                    "malformed MAT-file: " + std::to_string(budgets.size()) +
                        " variables in the file, libmatio read " + std::to_string(index));
  Mat_Rewind(mat.get());
  while (true) {
    VarPtr v(Mat_VarReadNext(mat.get()));
    if (!v) break;
    file.vars.push_back(std::move(v));
    if (file.vars.size() > 100000) break;
  }
  if (!log.text().empty())
    throw DataError(path, 0, "", "malformed or truncated MAT-file: " + log.text());
  if (file.vars.size() != index)
    throw DataError(path, 0, "",
                    "malformed MAT-file: read " + std::to_string(file.vars.size()) + " of " +
                        std::to_string(index) + " variables");
  return file;
}

// ---- loops ------------------------------------------------------------------------------------

using Fields = std::vector<std::pair<std::string, const matvar_t*>>;

struct Found {
  std::string path;
  const matvar_t* matrix = nullptr;  // set for a matrix
  Fields fields;                     // set for a loop struct
};

const matvar_t* field(const Fields& fs, std::string_view name) {
  const std::string want = lower(name);
  for (const auto& [n, v] : fs)
    if (lower(n) == want) return v;
  return nullptr;
}

bool is_loop(const Fields& fs) {
  const matvar_t* op = field(fs, "op");
  return op != nullptr && is_numeric_class(op->class_type);
}

void walk(const matvar_t* v, const std::string& path, std::vector<Found>& out, int depth) {
  if (v == nullptr || depth > 32 || out.size() > 100000) return;
  const std::size_t n = element_count(v);
  if (v->class_type == MAT_C_STRUCT) {
    auto* sv = const_cast<matvar_t*>(v);
    const unsigned nf = Mat_VarGetNumberOfFields(sv);
    char* const* names = Mat_VarGetStructFieldnames(sv);
    if (nf == 0 || names == nullptr) return;
    for (std::size_t k = 0; k < n; ++k) {
      const std::string at = n == 1 ? path : path + "(" + std::to_string(k + 1) + ")";
      Fields fs;
      for (unsigned i = 0; i < nf; ++i)
        fs.emplace_back(printable(names[i]), Mat_VarGetStructFieldByIndex(sv, i, k));
      if (is_loop(fs)) {
        out.push_back({at, nullptr, std::move(fs)});
        continue;
      }
      for (const auto& [name, child] : fs) walk(child, at + "." + name, out, depth + 1);
    }
  } else if (v->class_type == MAT_C_CELL) {
    if (v->data == nullptr) return;
    auto* cells = static_cast<matvar_t* const*>(v->data);
    for (std::size_t k = 0; k < n; ++k)
      walk(cells[k], path + "{" + std::to_string(k + 1) + "}", out, depth + 1);
  } else if (is_real_numeric(v) && v->rank == 2 && v->dims[0] >= 2 && v->dims[1] >= 2) {
    out.push_back({path, v, {}});
  }
}

std::vector<Found> find_loops(const File& file) {
  std::vector<Found> out;
  Fields top;
  for (const auto& v : file.vars) top.emplace_back(printable(v->name), v.get());
  if (is_loop(top)) {
    out.push_back({".", nullptr, std::move(top)});
    return out;
  }
  for (const auto& v : file.vars) walk(v.get(), printable(v->name), out, 0);
  return out;
}

std::optional<double> scalar(const matvar_t* v) {
  if (!is_real_numeric(v) || element_count(v) != 1) return std::nullopt;
  std::string why;
  auto x = values(v, why);
  if (!x) return std::nullopt;
  return (*x)[0];
}

std::optional<double> sample_time(const Fields& fs) {
  auto ts = scalar(field(fs, "ts"));
  if (ts && std::isfinite(*ts) && *ts > 0) return ts;
  return std::nullopt;
}

std::string list_text(const std::vector<Found>& loops, std::size_t most = 12) {
  std::string s;
  for (std::size_t i = 0; i < loops.size() && i < most; ++i) s += (i ? ", " : "") + loops[i].path;
  if (loops.size() > most) s += ", ... (" + std::to_string(loops.size() - most) + " more)";
  return s;
}

std::string field_names(const Fields& fs) {
  std::string s;
  for (const auto& f : fs) s += (s.empty() ? "" : ", ") + f.first;
  return s.empty() ? "none" : s;
}

const Found& resolve(const File& file, const std::vector<Found>& loops, const std::string& want) {
  if (loops.empty()) {
    std::string vars;
    for (const auto& v : file.vars)
      vars += (vars.empty() ? "" : ", ") + printable(v->name) + " (" + describe(v.get()) + ")";
    throw DataError(file.path, 0, "",
                    "no loop in the file: no struct with an OP field and no numeric matrix; "
                    "variables: " +
                        (vars.empty() ? "none" : vars));
  }
  if (want.empty()) {
    if (loops.size() == 1) return loops.front();
    throw DataError(file.path, 0, "",
                    std::to_string(loops.size()) + " loops in the file; choose one with --loop " +
                        "PATH: " + list_text(loops) +
                        (loops.size() > 12 ? " ('valvediag import FILE' lists them all)" : ""));
  }
  for (const auto& l : loops)
    if (l.path == want) return l;
  // A path may leave out leading parts: "chemicals.loop23" for "benchmark.chemicals.loop23".
  std::vector<const Found*> tails;
  for (const auto& l : loops)
    if (l.path.size() > want.size() && l.path.ends_with(want) &&
        l.path[l.path.size() - want.size() - 1] == '.')
      tails.push_back(&l);
  if (tails.size() == 1) return *tails.front();
  if (tails.size() > 1) {
    std::string s;
    for (const auto* t : tails) s += (s.empty() ? "" : ", ") + t->path;
    throw DataError(file.path, 0, "", "loop '" + want + "' is ambiguous: " + s);
  }
  throw DataError(file.path, 0, "",
                  "no loop '" + want + "'; loops in the file: " + list_text(loops) +
                      (loops.size() > 12 ? " ('valvediag import FILE' lists them all)" : ""));
}

bool all_digits(const std::string& s) {
  return !s.empty() && s.size() < 9 &&
         std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c); });
}

bool none(const std::string& s) {
  return lower(s) == "none";
}

}  // namespace

bool is_mat_file(const std::string& path) {
  return path.size() > 4 && lower(path.substr(path.size() - 4)) == ".mat";
}

MatFileInfo list_mat_loops(const std::string& path) {
  const File file = open_file(path);
  MatFileInfo info;
  info.format = file.format == Format::v73 ? "MATLAB v7.3 (HDF5)" : "MATLAB v5/v7";
  for (const Found& f : find_loops(file)) {
    MatLoopInfo l;
    l.path = f.path;
    if (f.matrix) {
      l.matrix = true;
      l.samples = f.matrix->dims[0];
      l.columns = f.matrix->dims[1];
    } else {
      for (const auto& fl : f.fields) {
        l.fields.push_back(fl.first);
        if (const auto x = scalar(fl.second); x && lower(fl.first) != "ts")
          l.scalars.emplace_back(fl.first, *x);
      }
      auto present = [&](const char* name) {
        const matvar_t* v = field(f.fields, name);
        return v != nullptr && is_real_numeric(v) && element_count(v) > 0;
      };
      l.has_op = present("op");
      l.has_pv = present("pv");
      l.has_sp = present("sp");
      l.has_mv = present("mv");
      l.samples = element_count(field(f.fields, "op"));
      l.ts = sample_time(f.fields);
    }
    info.loops.push_back(std::move(l));
  }
  return info;
}

LoopData read_mat_loop(const std::string& path, const std::string& loop, const MatOptions& o,
                       std::vector<std::string>* notes) {
  const File file = open_file(path);
  const std::vector<Found> loops = find_loops(file);
  const Found& f = resolve(file, loops, loop);
  const std::string where = "loop '" + f.path + "'";
  auto fail = [&](const std::string& problem) -> DataError {
    return DataError(path, 0, "", where + ": " + problem);
  };
  auto note = [&](const std::string& s) {
    if (notes) notes->push_back(s);
  };
  // Before the values are copied out: the same bound and message as a CSV file's.
  auto check_rows = [&](std::size_t n, const std::string& what) {
    if (n > o.max_rows)
      throw fail(what + " has " + std::to_string(n) + " samples, more than " +
                 std::to_string(o.max_rows) +
                 ", the --max-rows limit that keeps memory bounded (about 50 bytes a row); give "
                 "--max-rows with a larger number to read it all, or cut the record into "
                 "shorter ones");
  };
  LoopData d;
  d.source = path + ":" + f.path;
  std::optional<double> period = o.sample_period;
  if (period && !(std::isfinite(*period) && *period > 0))
    throw fail("the sample period must be a positive number of seconds");

  if (f.matrix) {
    const std::size_t rows = f.matrix->dims[0], cols = f.matrix->dims[1];
    check_rows(rows, "the matrix");
    std::string why;
    auto all = values(f.matrix, why);
    if (!all) throw fail("the matrix " + why);
    const std::string shape = std::to_string(rows) + " x " + std::to_string(cols) + " matrix";
    auto column = [&](const std::string& spec, const char* role) -> std::vector<double> {
      if (!all_digits(spec))
        throw fail("a " + shape + " (samples in rows): name its " + role +
                   " column by number, 1 to " + std::to_string(cols) + " (--" + role +
                   " N), not '" + spec + "'");
      const std::size_t c = std::stoul(spec);
      if (c < 1 || c > cols)
        throw fail(std::string(role) + " column " + spec + " is outside 1.." +
                   std::to_string(cols) + " of the " + shape);
      return {all->begin() + static_cast<std::ptrdiff_t>((c - 1) * rows),
              all->begin() + static_cast<std::ptrdiff_t>(c * rows)};
    };
    d.op = column(o.op, "op");
    if (!o.pv.empty() && !none(o.pv)) d.pv = column(o.pv, "pv");
    if (!o.sp.empty() && !none(o.sp)) d.sp = column(o.sp, "sp");
    if (!o.mv.empty() && !none(o.mv)) d.mv = column(o.mv, "mv");
    if (!d.has_pv() && o.require_pv)
      throw fail("no pv column given; name it by number (--pv N, 1 to " + std::to_string(cols) +
                 ")");
    const bool time_column = !o.t.empty() && !none(o.t) && lower(o.t) != "t";
    if (time_column) {
      d.t = column(o.t, "t");
      for (std::size_t i = 1; i < d.t.size(); ++i)
        if (!(d.t[i] > d.t[i - 1]) || !std::isfinite(d.t[i]))
          throw fail("time column " + o.t + " does not increase at row " + std::to_string(i + 1));
      std::vector<double> steps(d.t.size() - 1);
      for (std::size_t i = 1; i < d.t.size(); ++i) steps[i - 1] = d.t[i] - d.t[i - 1];
      std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2),
                       steps.end());
      const double median = steps[steps.size() / 2];
      for (std::size_t i = 1; i < d.t.size(); ++i)
        if (std::abs(d.t[i] - d.t[i - 1] - median) > 0.01 * median)
          throw fail("irregular sampling in time column " + o.t + " at row " +
                     std::to_string(i + 1) + " (step " + num6g(d.t[i] - d.t[i - 1]) +
                     " s, median " + num6g(median) + " s); export it to CSV and use --resample");
      if (period && std::abs(*period - median) > 0.01 * median)
        throw fail("the sample period " + num6g(*period) + " s disagrees with time column " + o.t +
                   " (" + num6g(median) + " s)");
    } else {
      if (!period)
        throw fail("a " + shape + " has no sample period: give it (--sample-period S, s)");
      d.t.resize(rows);
      for (std::size_t i = 0; i < rows; ++i) d.t[i] = static_cast<double>(i) * *period;
    }
    note("read " + where + " (" + shape + "): op column " + o.op +
         (d.has_pv() ? ", pv column " + o.pv : "") + (d.sp.empty() ? "" : ", sp column " + o.sp) +
         (d.mv.empty() ? "" : ", mv column " + o.mv) +
         (time_column ? ", t column " + o.t : ", Ts " + num6g(*period) + " s"));
  } else {
    const Fields& fs = f.fields;
    auto get = [&](const std::string& spec, const char* role, bool required) {
      std::vector<double> v;
      if (none(spec)) return v;
      if (all_digits(spec))
        throw fail(
            "columns by number name the columns of a matrix; this loop is a struct with "
            "fields " +
            field_names(fs) + ": give a field name (--" + role + " NAME)");
      const std::string name = spec.empty() ? role : spec;
      const matvar_t* fv = field(fs, name);
      if (fv == nullptr) {
        if (!required && (spec.empty() || lower(spec) == role)) return v;  // optional, default name
        std::string up = name;
        for (char& c : up) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
        throw fail("no " + up + " field (fields present: " + field_names(fs) + ")" +
                   (std::string_view(role) == "pv"
                        ? "; identification needs the process variable next to OP"
                        : ""));
      }
      check_rows(element_count(fv), "field " + name);
      std::string why;
      auto x = values(fv, why);
      if (!x) throw fail("field " + name + " " + why);
      if (!is_vector(fv)) throw fail("field " + name + " is " + describe(fv) + ", not a vector");
      return std::move(*x);
    };
    d.op = get(o.op, "op", true);
    d.pv = get(o.pv, "pv", o.require_pv);
    d.sp = get(o.sp, "sp", false);
    d.mv = get(o.mv, "mv", false);
    const matvar_t* tsv = field(fs, "ts");
    std::optional<double> ts = sample_time(fs);
    if (tsv != nullptr && element_count(tsv) > 0 && !ts)
      throw fail("field Ts must be one positive number of seconds, but is " + describe(tsv));
    if (ts && period && std::abs(*ts - *period) > 0.01 * *ts)
      throw fail("the sample period " + num6g(*period) + " s disagrees with Ts = " + num6g(*ts) +
                 " s in the file");
    if (!ts && !period)
      throw fail("no Ts field (fields present: " + field_names(fs) +
                 "): give the sample period (--sample-period S, s)");
    const double P = ts ? *ts : *period;
    d.t.resize(d.op.size());
    for (std::size_t i = 0; i < d.t.size(); ++i) d.t[i] = static_cast<double>(i) * P;
    std::string used = "op";
    if (d.has_pv()) used += ", pv";
    if (!d.sp.empty()) used += ", sp";
    if (!d.mv.empty()) used += ", mv";
    note("read " + where + ": " + used + ", Ts " + num6g(P) + " s" + (ts ? "" : " (given)") +
         (!d.has_pv() ? "; no PV field" : ""));
  }
  // Aligned, finite series of at least two samples.
  auto check = [&](const std::vector<double>& v, const char* name) {
    if (v.empty()) return;
    if (v.size() != d.op.size())
      throw fail(std::string(name) + " has " + std::to_string(v.size()) + " samples but op has " +
                 std::to_string(d.op.size()) + " (the series must be aligned)");
    for (std::size_t i = 0; i < v.size(); ++i)
      if (const std::string why = signal_value_problem(v[i]); !why.empty())
        throw fail(std::string(name) + " sample " + std::to_string(i + 1) + ": " + why);
  };
  check(d.op, "op");
  check(d.pv, "pv");
  check(d.sp, "sp");
  check(d.mv, "mv");
  if (d.op.size() < 2)
    throw fail("only " + std::to_string(d.op.size()) + " sample(s); at least 2 are needed");
  return d;
}

}  // namespace valvediag
