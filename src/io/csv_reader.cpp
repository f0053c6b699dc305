#include "valvediag/io/csv_reader.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <system_error>
#include <utility>

#include "time_parse.hpp"
#include "valvediag/io/data_checks.hpp"
#include "valvediag/io/data_error.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag {
namespace {

constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
// Resampling makes at most this many samples (and at most 100 per row beyond 10^6).
constexpr double kMaxGridPoints = 2e7;
// Longer lines are not data rows: a row of even a few hundred columns is some kilobytes.
constexpr std::size_t kMaxLineBytes = std::size_t{1} << 20;

bool is_blank(char c) {
  return c == ' ' || c == '\t';
}

char lower(char c) {
  return (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c;
}

// A cell or name as it appears in messages: quoted, shortened, control bytes made visible.
std::string show(std::string_view s) {
  constexpr std::size_t kMax = 40;
  std::string out = "'";
  for (std::size_t i = 0; i < s.size() && i < kMax; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    out += c < 0x20 || c == 0x7f ? '?' : s[i];
  }
  if (s.size() > kMax) out += "...";
  return out + "'";
}

// Physical lines of text in memory, or of a file read in chunks so that memory stays bounded
// whatever the file's size. The line end is LF (optionally after CR), or CR alone when the
// first window (the text, or the first kMaxLineBytes of a file) has no LF. A line longer than
// kMaxLineBytes is refused at its line number: no line end within it means binary data or a
// device like /dev/zero, and reading on would only fill memory.
class Lines {
 public:
  Lines(std::string_view text, const std::string& file) : file_(file), data_(text) {
    eol_ = text.find('\n') != std::string_view::npos || text.find('\r') == std::string_view::npos
               ? '\n'
               : '\r';
  }
  // `head`: the file's first bytes, already read from f.
  Lines(std::FILE* f, const std::string& file, std::string head = {})
      : file_(file), f_(f), buf_(std::move(head)), data_(buf_), eof_(false) {
    for (std::size_t old = 0; std::memchr(buf_.data() + old, '\n', buf_.size() - old) == nullptr;) {
      if (eof_ || buf_.size() > kMaxLineBytes) break;
      old = buf_.size();
      fill();
    }
    eol_ =
        buf_.find('\n') != std::string::npos || buf_.find('\r') == std::string::npos ? '\n' : '\r';
  }

  // The bytes at the start of the text (all of it in memory, at least the first line of a file),
  // for the byte-order-mark checks before the first next().
  std::string_view start() const { return data_.substr(pos_); }
  void skip(std::size_t n) { pos_ += n; }

  bool next(std::string_view& line) {
    const void* hit = nullptr;
    for (std::size_t scanned = 0;;) {
      hit = std::memchr(data_.data() + pos_ + scanned, eol_, data_.size() - pos_ - scanned);
      const std::size_t rest = data_.size() - pos_;
      if (hit != nullptr || rest > kMaxLineBytes || eof_) break;
      scanned = rest;
      buf_.erase(0, pos_);  // keep only the line being read
      pos_ = 0;
      fill();
    }
    if (pos_ >= data_.size()) return false;
    const char* begin = data_.data() + pos_;
    const std::size_t rest = data_.size() - pos_;
    std::size_t len = hit ? static_cast<std::size_t>(static_cast<const char*>(hit) - begin) : rest;
    if (len > kMaxLineBytes)
      throw DataError(file_, number_ + 1, "",
                      "the line is longer than " + std::to_string(kMaxLineBytes >> 20) +
                          " MiB (no line end within it): this is not a text data file (binary "
                          "data, or a device such as /dev/zero?); give a CSV file");
    pos_ += len + (hit ? 1 : 0);
    if (eol_ == '\n' && len > 0 && begin[len - 1] == '\r') --len;
    line = std::string_view(begin, len);
    ++number_;
    return true;
  }
  std::size_t number() const { return number_; }

 private:
  // Appends the next chunk of the file to buf_.
  void fill() {
    constexpr std::size_t kChunk = 1 << 16;
    const std::size_t old = buf_.size();
    buf_.resize(old + kChunk);
    const std::size_t k = std::fread(buf_.data() + old, 1, kChunk, f_);
    buf_.resize(old + k);
    data_ = buf_;
    if (k == kChunk) return;
    if (std::ferror(f_))
      throw DataError(file_, 0, "",
                      "reading the file failed: " + std::generic_category().message(errno));
    eof_ = true;
  }

  const std::string& file_;
  std::FILE* f_ = nullptr;
  std::string buf_;        // file mode: the unread part of the file read so far
  std::string_view data_;  // the text, or buf_
  bool eof_ = true;
  char eol_ = '\n';
  std::size_t pos_ = 0;
  std::size_t number_ = 0;
};

bool blank_or_comment(std::string_view line) {
  for (char c : line) {
    if (is_blank(c) || c == '\r') continue;
    return c == '#';
  }
  return true;
}

struct Delimiter {
  char c = ',';
  bool blanks = false;  // runs of spaces and tabs
  bool detect = false;
};

Delimiter parse_delimiter(const std::string& spec, char decimal, const std::string& file) {
  Delimiter d;
  if (spec.empty() || spec == "auto") {
    d.detect = true;
  } else if (spec == "tab" || spec == "\\t" || spec == "\t") {
    d.c = '\t';
  } else if (spec == "space" || spec == "whitespace" || spec == " ") {
    d.blanks = true;
  } else if (spec == "comma") {
    d.c = ',';
  } else if (spec == "semicolon") {
    d.c = ';';
  } else if (spec.size() == 1 && std::ispunct(static_cast<unsigned char>(spec[0])) &&
             std::string_view("\"#.-+").find(spec[0]) == std::string_view::npos) {
    d.c = spec[0];
  } else {
    throw DataError(file, 0, "",
                    "--delimiter " + show(spec) +
                        " is not usable (use ',', ';', 'tab', 'space', '|' or 'auto')");
  }
  if (!d.detect && !d.blanks && d.c == decimal)
    throw DataError(
        file, 0, "",
        std::string("--delimiter and the decimal separator are both '") + decimal + "'");
  return d;
}

// Tab if present, else ';' or ',' (whichever is more frequent), else blanks. The header row
// has no decimal commas, so ';' files with decimal commas are found too.
Delimiter detect_delimiter(std::string_view header, char decimal) {
  std::size_t tabs = 0, semis = 0, commas = 0, blanks = 0;
  bool quoted = false;
  for (char c : header) {
    if (c == '"') quoted = !quoted;
    if (quoted) continue;
    tabs += c == '\t';
    semis += c == ';';
    commas += c == ',';
    blanks += c == ' ';
  }
  if (decimal == ',') commas = 0;
  Delimiter d;
  if (tabs > 0) {
    d.c = '\t';
  } else if (semis > 0 || commas > 0) {
    d.c = semis >= commas ? ';' : ',';
  } else if (blanks > 0) {
    d.blanks = true;
  } else {
    d.c = decimal == ',' ? ';' : ',';  // one column; the column lookup then says what is there
  }
  return d;
}

enum class Split { ok, unterminated_quote, text_after_quote };

class Splitter {
 public:
  explicit Splitter(Delimiter d) : d_(d) {}

  // Cells of `line`, at most max_cells of them. Surrounding blanks are trimmed; a cell in
  // double quotes may hold the delimiter, and "" stands for a quote.
  Split split(std::string_view line, std::size_t max_cells, std::vector<std::string_view>& cells) {
    cells.clear();
    unescaped_.clear();
    const std::size_t n = line.size();
    std::size_t pos = 0;
    if (d_.blanks) {
      while (pos < n && is_blank(line[pos])) ++pos;
      if (pos >= n) return Split::ok;
    }
    while (cells.size() < max_cells) {
      std::size_t p = pos;
      while (p < n && trim(line[p])) ++p;
      std::size_t next;  // where the following cell starts, n when none follows
      if (p < n && line[p] == '"') {
        const std::size_t start = ++p;
        bool escaped = false;
        for (;;) {
          const void* q = std::memchr(line.data() + p, '"', n - p);
          if (q == nullptr) return Split::unterminated_quote;
          p = static_cast<std::size_t>(static_cast<const char*>(q) - line.data());
          if (p + 1 < n && line[p + 1] == '"') {
            escaped = true;
            p += 2;
            continue;
          }
          break;
        }
        std::string_view content = line.substr(start, p - start);
        if (escaped) {
          std::string s;
          for (std::size_t i = 0; i < content.size(); ++i) {
            s += content[i];
            if (content[i] == '"') ++i;
          }
          unescaped_.push_back(std::move(s));
          content = unescaped_.back();
        }
        cells.push_back(content);
        ++p;
        while (p < n && trim(line[p])) ++p;
        if (p < n && !delimiter(line[p])) return Split::text_after_quote;
        next = p;
      } else {
        std::size_t end = p;
        if (d_.blanks) {
          while (end < n && !is_blank(line[end])) ++end;
        } else {
          const void* q = std::memchr(line.data() + p, d_.c, n - p);
          end = q ? static_cast<std::size_t>(static_cast<const char*>(q) - line.data()) : n;
        }
        std::size_t e = end;
        while (e > p && trim(line[e - 1])) --e;
        cells.push_back(line.substr(p, e - p));
        next = end;
      }
      if (next >= n) return Split::ok;
      if (d_.blanks) {
        while (next < n && is_blank(line[next])) ++next;
        if (next >= n) return Split::ok;
        pos = next;
      } else {
        pos = next + 1;  // a delimiter at the very end leaves one empty cell
      }
    }
    return Split::ok;
  }

 private:
  // A stray CR (from CR CR LF line ends) is trimmed like a blank.
  bool trim(char c) const { return c == ' ' || c == '\r' || (c == '\t' && d_.c != '\t'); }
  bool delimiter(char c) const { return d_.blanks ? is_blank(c) : c == d_.c; }

  Delimiter d_;
  std::deque<std::string> unescaped_;  // deque: views into earlier cells stay valid
};

enum class Num { ok, empty, bad, not_finite, out_of_range };

Num parse_number(std::string_view s, char decimal, std::string& buf, double& v) {
  if (s.empty()) return Num::empty;
  if (s[0] == '+') {
    s.remove_prefix(1);
    if (s.empty() || s[0] == '+' || s[0] == '-') return Num::bad;
  }
  if (decimal == ',') {
    // "1.234" must not silently become 1.234 when the file writes 1234 with a decimal comma.
    if (s.find('.') != std::string_view::npos) return Num::bad;
    buf.assign(s);
    std::replace(buf.begin(), buf.end(), ',', '.');
    s = buf;
  }
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec == std::errc::result_out_of_range) return Num::out_of_range;
  if (ec != std::errc() || ptr != s.data() + s.size()) return Num::bad;
  if (!std::isfinite(v)) return Num::not_finite;
  return Num::ok;
}

bool looks_numeric(std::string_view s) {
  std::string buf;
  double v = 0;
  const Num r = parse_number(s, '.', buf, v);
  return r == Num::ok || r == Num::not_finite;
}

bool all_digits(std::string_view s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

bool iequal(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (lower(a[i]) != lower(b[i])) return false;
  return true;
}

// Case-insensitive wildcard match: '*' any run, '?' one character. Linear backtracking over the
// last '*', so long names cannot make it slow.
bool glob(std::string_view pat, std::string_view s) {
  std::size_t p = 0, i = 0, star = std::string_view::npos, mark = 0;
  while (i < s.size()) {
    if (p < pat.size() && (pat[p] == '?' || lower(pat[p]) == lower(s[i]))) {
      ++p;
      ++i;
    } else if (p < pat.size() && pat[p] == '*') {
      star = p++;
      mark = i;
    } else if (star != std::string_view::npos) {
      p = star + 1;
      i = ++mark;
    } else {
      return false;
    }
  }
  while (p < pat.size() && pat[p] == '*') ++p;
  return p == pat.size();
}

struct Column {
  Column(const char* role_, const char* flag_, std::string spec_, bool required_)
      : role(role_), flag(flag_), spec(std::move(spec_)), required(required_) {}
  const char* role;  // t, op, pv, sp, mv
  const char* flag;  // the CLI option that chooses it, for hints
  std::string spec;  // as given
  bool required;
  std::size_t index = kNone;
  std::string name;  // header name, or "column N" when the header cell is empty
};

std::string list_names(const std::vector<std::string_view>& names) {
  constexpr std::size_t kMax = 30;
  std::string s;
  for (std::size_t i = 0; i < names.size() && i < kMax; ++i) {
    if (i) s += ", ";
    s += show(names[i]);
  }
  if (names.size() > kMax) s += ", ... (" + std::to_string(names.size()) + " in all)";
  return s;
}

void resolve(Column& col, const std::vector<std::string_view>& names, const std::string& file,
             std::size_t header_line, bool header_numeric) {
  auto set = [&](std::size_t i) {
    col.index = i;
    col.name = names[i].empty() ? "column " + std::to_string(i + 1) : std::string(names[i]);
  };
  const std::string& spec = col.spec;
  if (all_digits(spec)) {
    const std::size_t number = spec.size() > 9 ? kNone : std::stoul(spec);
    if (number == 0)
      throw DataError(file, header_line, spec, "column numbers start at 1", col.role);
    if (number > names.size())
      throw DataError(file, header_line, spec,
                      "there is no column " + spec + ": the header row has " +
                          std::to_string(names.size()) + " columns (" + list_names(names) + ")",
                      col.role);
    set(number - 1);
    return;
  }
  const bool wildcard = spec.find_first_of("*?") != std::string::npos;
  std::vector<std::size_t> hits;
  for (int pass = 0; pass < 3 && hits.empty(); ++pass) {
    if (pass == 2 && !wildcard) break;
    for (std::size_t i = 0; i < names.size(); ++i) {
      if (names[i].empty()) continue;
      const bool match = pass == 0   ? names[i] == spec
                         : pass == 1 ? iequal(names[i], spec)
                                     : glob(spec, names[i]);
      if (match) hits.push_back(i);
    }
  }
  if (hits.size() == 1) {
    set(hits[0]);
    return;
  }
  if (hits.size() > 1) {
    std::vector<std::string_view> matched;
    for (std::size_t i : hits) matched.push_back(names[i]);
    throw DataError(file, header_line, spec,
                    "matches " + std::to_string(hits.size()) + " columns (" + list_names(matched) +
                        "); choose one with " + col.flag + " NAME or " + col.flag + " NUMBER",
                    col.role);
  }
  if (!col.required) return;
  std::string problem = "not found in the header row (columns: " + list_names(names) +
                        "); choose the " + col.role + " column with " + col.flag + " NAME or " +
                        col.flag + " NUMBER (1-based)";
  if (header_numeric)
    problem += "; the header row looks like data: check --skip-lines";
  else if (names.size() == 1)
    problem += "; only one column was found: check --delimiter";
  throw DataError(file, header_line, spec, problem, col.role);
}

// --t DATE+TIME: the two column specs of a stamp split over a date and a time-of-day column
// (exactly one '+'); nullopt for any other spec. Callers try the whole spec as one name first.
std::optional<std::pair<std::string, std::string>> date_time_parts(const std::string& spec) {
  const std::size_t plus = spec.find('+');
  if (plus == std::string::npos || spec.find('+', plus + 1) != std::string::npos) return {};
  return std::pair{spec.substr(0, plus), spec.substr(plus + 1)};
}

// ---- Format "auto": the layout sniffed from the first lines ----

constexpr std::size_t kSniffLines = 200;
constexpr std::size_t kSniffBytes = std::size_t{1} << 20;

// The usual historian stamps (%S also takes a fraction); day/month order is left to the data.
constexpr std::string_view kTimeFormats[] = {
    "%Y-%m-%d %H:%M:%S", "%Y-%m-%dT%H:%M:%S", "%Y/%m/%d %H:%M:%S", "%d.%m.%Y %H:%M:%S",
    "%m/%d/%Y %H:%M:%S", "%d/%m/%Y %H:%M:%S", "%Y-%m-%d %H:%M",    "%d.%m.%Y %H:%M",
    "%m/%d/%Y %H:%M",    "%d/%m/%Y %H:%M"};

bool is_time_stamp(std::string_view cell) {
  detail::TimeStamp ts;
  std::string why;
  for (std::string_view f : kTimeFormats)
    if (detail::parse_time_stamp(cell, f, ts, why)) return true;
  return false;
}

// The formats that read every stamp in `cells`; of those, the ones under which time increases,
// and of these the ones with regular steps, when there are any: the data decide a day/month
// order that runs backwards or jumps a month at midnight.
std::vector<std::string_view> matching_time_formats(const std::vector<std::string>& cells) {
  std::vector<std::string_view> all, increasing, regular;
  for (std::string_view f : kTimeFormats) {
    std::vector<double> t;
    for (const std::string& c : cells) {
      detail::TimeStamp ts;
      std::string why;
      if (!detail::parse_time_stamp(c, f, ts, why)) break;
      t.push_back(static_cast<double>(ts.seconds) + ts.fraction);
    }
    if (t.empty() || t.size() < cells.size()) continue;
    all.push_back(f);
    std::vector<double> steps;
    for (std::size_t i = 1; i < t.size(); ++i) steps.push_back(t[i] - t[i - 1]);
    if (std::any_of(steps.begin(), steps.end(), [](double d) { return !(d > 0); })) continue;
    increasing.push_back(f);
    const auto [lo, hi] = std::minmax_element(steps.begin(), steps.end());
    if (steps.empty() || *hi - *lo <= kSamplingTolerance * *lo) regular.push_back(f);
  }
  return !regular.empty() ? regular : !increasing.empty() ? increasing : all;
}

bool is_number(std::string_view cell) {
  std::string buf;
  double v = 0;
  return parse_number(cell, '.', buf, v) == Num::ok || parse_number(cell, ',', buf, v) == Num::ok;
}

// A row of text: no cell is a number or a time stamp (units, descriptions, a second header).
bool text_row(const std::vector<std::string_view>& cells) {
  return std::none_of(cells.begin(), cells.end(),
                      [](std::string_view c) { return is_number(c) || is_time_stamp(c); });
}

// The most frequent value of `v` (the smallest of equals) and how often it occurs; {0, 0} when
// v is empty.
std::pair<std::size_t, std::size_t> most_common(std::vector<std::size_t> v) {
  std::sort(v.begin(), v.end());
  std::pair<std::size_t, std::size_t> best{0, 0};
  for (std::size_t i = 0, j = 0; i < v.size(); i = j) {
    while (j < v.size() && v[j] == v[i]) ++j;
    if (j - i > best.second) best = {v[i], j - i};
  }
  return best;
}

// Lines of the head of a file (the whole text when `whole`, else without its cut last line).
std::vector<std::string_view> head_lines(std::string_view head, bool whole) {
  if (head.substr(0, 3) == "\xEF\xBB\xBF") head.remove_prefix(3);
  const char eol =
      head.find('\n') != std::string_view::npos || head.find('\r') == std::string_view::npos ? '\n'
                                                                                             : '\r';
  std::vector<std::string_view> out;
  std::size_t pos = 0;
  while (pos < head.size() && out.size() < kSniffLines) {
    std::size_t e = head.find(eol, pos);
    if (e == std::string_view::npos) {
      if (!whole) break;
      e = head.size();
    }
    std::string_view l = head.substr(pos, e - pos);
    if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
    out.push_back(l);
    pos = e + 1;
  }
  return out;
}

// Cells of a line without trailing empty ones (a delimiter at the end of every row); 0 for a
// line the splitter refuses.
std::size_t split_trimmed(Splitter& s, std::string_view line,
                          std::vector<std::string_view>& cells) {
  if (s.split(line, kNone, cells) != Split::ok) return 0;
  while (!cells.empty() && cells.back().empty()) cells.pop_back();
  return cells.size();
}

std::string delimiter_option(Delimiter d) {
  if (d.blanks) return "space";
  if (d.c == '\t') return "tab";
  return std::string(1, d.c);
}

// A value as the shell takes it: quoted unless plain.
std::string shell_word(std::string_view s) {
  const bool plain = !s.empty() && std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || std::strchr("_.,:/=+-", c) != nullptr;
  });
  if (plain) return std::string(s);
  std::string out = "'";
  for (char c : s) {
    if (c == '\'') out += "'\\'";  // close, escaped quote, reopen
    out += c;
  }
  out += '\'';
  return out;
}

// " or " and the next format, for lists of --time-format choices.
std::string shell_words_sep(const std::string& so_far, std::string_view format) {
  std::string s = so_far.empty() ? std::string() : std::string(" or ");
  s += shell_word(format);
  return s;
}

// Columns whose name ends in one of `suffixes` (case-insensitive).
std::vector<std::size_t> tagged(const std::vector<std::string>& names,
                                std::initializer_list<std::string_view> suffixes) {
  std::vector<std::size_t> hits;
  for (std::size_t i = 0; i < names.size(); ++i)
    for (std::string_view suf : suffixes)
      if (names[i].size() > suf.size() &&
          iequal(std::string_view(names[i]).substr(names[i].size() - suf.size()), suf)) {
        hits.push_back(i);
        break;
      }
  return hits;
}

bool has_name(const std::vector<std::string>& names, std::string_view name) {
  return std::any_of(names.begin(), names.end(),
                     [&](const std::string& n) { return iequal(n, name); });
}

// The layout of `head` (the file's first bytes; `whole`: all of it), the fields in opt.given
// kept. `read_as` gets the chosen options that differ from format "plain", as the user would
// type them.
CsvOptions sniff_layout(std::string_view head, bool whole, const CsvOptions& opt,
                        const std::string& file, std::string& read_as) {
  CsvOptions o = opt;
  const CsvGiven& g = opt.given;
  // UTF-16 or binary: the reader says what is wrong with it.
  if (head.substr(0, 2) == "\xFF\xFE" || head.substr(0, 2) == "\xFE\xFF" ||
      head.substr(0, 4096).find('\0') != std::string_view::npos)
    return o;
  const std::vector<std::string_view> lines = head_lines(head, whole);
  std::vector<std::size_t> used;  // the lines that are neither blank nor comments
  for (std::size_t i = 0; i < lines.size(); ++i)
    if (!blank_or_comment(lines[i])) used.push_back(i);
  if (used.empty()) return o;

  // Delimiter: the one that splits the most lines of the head's second half (data) into the
  // same number (at least 2) of cells: a truncated row there does not decide it. Ties go to the
  // earlier in this list (';' before ',' for decimal commas, anything before blanks for
  // date-time stamps).
  std::vector<std::string_view> cells;
  Delimiter delim;
  bool found = false;
  std::size_t width = 0;  // cells in a data row
  if (g.delimiter && opt.delimiter != "auto") {
    delim = parse_delimiter(opt.delimiter, opt.decimal, file);
    found = true;
  } else {
    std::size_t best = 0;
    for (const char* spec : {"tab", ";", ",", "|", "space"}) {
      const Delimiter d = parse_delimiter(spec, '.', file);
      if (g.decimal && opt.decimal == ',' && d.c == ',' && !d.blanks) continue;
      Splitter s(d);
      std::vector<std::size_t> counts;
      for (std::size_t j = used.size() / 2; j < used.size(); ++j)
        counts.push_back(split_trimmed(s, lines[used[j]], cells));
      const auto [k, times] = most_common(counts);
      if (k >= 2 && times > best) {
        best = times;
        delim = d;
        width = k;
        found = true;
      }
    }
    if (!found) return o;  // one column: the reader names what it found
    o.delimiter = delimiter_option(delim);
  }
  Splitter split(delim);
  if (width == 0) {
    std::vector<std::size_t> counts;
    for (std::size_t j = used.size() / 2; j < used.size(); ++j)
      counts.push_back(split_trimmed(split, lines[used[j]], cells));
    width = most_common(counts).first;
  }

  // The data: from the first row of `width` cells, at least half numbers and time stamps, that the
  // next rows (up to 3) continue. A bad row further on stays data, for the reader to name.
  auto data_like = [&](std::size_t i) {
    if (split_trimmed(split, lines[i], cells) != width) return false;
    std::size_t filled = 0, values = 0;
    for (std::string_view c : cells) {
      filled += !c.empty();
      values += is_number(c) || is_time_stamp(c);
    }
    return 2 * values >= filled && values > 0;
  };
  std::size_t first = kNone;  // index into used
  for (std::size_t j = 0; j < used.size() && first == kNone; ++j) {
    bool ok = true;
    for (std::size_t k = j; k < used.size() && k <= j + 3 && ok; ++k) ok = data_like(used[k]);
    if (ok) first = j;
  }
  if (first == kNone) return o;
  // The header: the first line of the data's width before it (title lines are narrower), else
  // the line just before the data; none when the data start at once.
  std::size_t header = kNone;
  if (g.skip_lines) {
    for (std::size_t j = 0; j < used.size() && header == kNone; ++j)
      if (used[j] >= opt.skip_lines) header = j;
  } else {
    for (std::size_t j = 0; j < first && header == kNone; ++j)
      if (split_trimmed(split, lines[used[j]], cells) == width) header = j;
    if (header == kNone && first > 0) header = first - 1;
    if (header != kNone) o.skip_lines = header == 0 ? 0 : used[header];
  }
  if (header == kNone || header >= first) return o;
  // The data start at the first row after the header that is not all text: a malformed row
  // among the first ones is data, for the reader to name, never skipped.
  for (std::size_t j = header + 1; j < first; ++j) {
    split.split(lines[used[j]], kNone, cells);
    if (!text_row(cells)) {
      first = j;
      break;
    }
  }
  if (!g.skip_after_header)
    o.skip_after_header = header + 1 == first ? 0 : used[first] - used[header] - 1;

  split.split(lines[used[header]], kNone, cells);
  const std::vector<std::string> names(cells.begin(), cells.end());
  // Every data row of the head, for the time column and the decimal separator.
  std::vector<std::vector<std::string>> rows;
  for (std::size_t j = first; j < used.size(); ++j) {
    split.split(lines[used[j]], kNone, cells);
    rows.emplace_back(cells.begin(), cells.end());
  }
  auto column_cells = [&](std::size_t c) {
    std::vector<std::string> out;
    for (const auto& r : rows)
      if (c < r.size() && !r[c].empty()) out.push_back(r[c]);
    return out;
  };

  if (!g.decimal && delim.c != ',') {
    std::size_t dots = 0, commas = 0;
    std::string buf;
    double v = 0;
    for (const auto& r : rows)
      for (const std::string& c : r) {
        dots += c.find('.') != std::string::npos && parse_number(c, '.', buf, v) == Num::ok;
        commas += c.find(',') != std::string::npos && parse_number(c, ',', buf, v) == Num::ok;
      }
    if (commas > 0 && dots == 0) o.decimal = ',';
  }

  // Historian tags; plain op/pv/sp names keep today's meaning.
  auto tag = [&](bool given, std::string& spec, std::string_view plain, const char* flag,
                 std::initializer_list<std::string_view> suffixes, const char* also) {
    if (given || has_name(names, plain)) return;
    const std::vector<std::size_t> hits = tagged(names, suffixes);
    if (hits.size() == 1) {
      const std::string& n = names[hits[0]];
      spec = "*" + n.substr(n.rfind('.'));
      return;
    }
    if (hits.empty()) return;
    std::vector<std::string_view> shown;
    for (std::size_t i : hits) shown.push_back(names[i]);
    std::string ends;
    for (std::string_view s : suffixes) {
      if (!ends.empty()) ends += '/';
      ends += s;
    }
    throw DataError(file, used[header] + 1, "",
                    std::to_string(hits.size()) + " columns end in " + ends + ": " +
                        list_names(shown) + "; choose one with " + flag + " NAME" + also);
  };
  tag(g.op, o.op_column, "op", "--op", {".MV", ".OP", ".OUT"}, "");
  tag(g.pv, o.pv_column, "pv", "--pv", {".PV"}, "");
  tag(g.sp, o.sp_column, "sp", "--sp", {".SV", ".SP"}, " (or --sp none)");

  // A date column beside a time-of-day column: one stamp in two cells, read joined by a space.
  auto joined_cells = [&](std::size_t a, std::size_t b) {
    std::vector<std::string> out;
    for (const auto& r : rows)
      if (a < r.size() && b < r.size() && !r[a].empty() && !r[b].empty())
        out.push_back(r[a] + " " + r[b]);
    return out;
  };
  auto stamps_of = [&](std::size_t c) { return !matching_time_formats(column_cells(c)).empty(); };
  auto split_stamps_at = [&](std::size_t c) {
    return c + 1 < names.size() && !matching_time_formats(joined_cells(c, c + 1)).empty();
  };
  // --t for columns c and c + 1: by name when both names are plain, else by number.
  auto pair_spec = [&](std::size_t c) {
    const auto plain = [&](const std::string& n) {
      return !n.empty() && n.find_first_of("+*?") == std::string::npos &&
             std::count_if(names.begin(), names.end(),
                           [&](const std::string& m) { return iequal(m, n); }) == 1;
    };
    return plain(names[c]) && plain(names[c + 1])
               ? names[c] + "+" + names[c + 1]
               : std::to_string(c + 1) + "+" + std::to_string(c + 2);
  };

  // The time column: t or time by name (a `time` of day after a date column: the two), else the
  // first column of date-time stamps, else the first date and time-of-day pair.
  std::size_t t_index = kNone;
  bool t_split = false;
  if (!g.t && !has_name(names, "t")) {
    std::size_t named = kNone;
    for (std::size_t c = 0; c < names.size(); ++c)
      if (iequal(names[c], "time")) named = c;
    if (named != kNone && named > 0 && !stamps_of(named - 1) && split_stamps_at(named - 1)) {
      t_index = named - 1;
      t_split = true;
    } else if (named != kNone) {
      o.t_column = "time";
    } else {
      for (std::size_t c = 0; c < names.size() && t_index == kNone; ++c)
        if (stamps_of(c)) t_index = c;
      // No single column of stamps: the first neighbouring pair that reads as one.
      for (std::size_t c = 0; c + 1 < names.size() && t_index == kNone; ++c)
        if (split_stamps_at(c)) {
          t_index = c;
          t_split = true;
        }
    }
    if (t_index != kNone) o.t_column = t_split ? pair_spec(t_index) : std::to_string(t_index + 1);
  }
  if (!g.time_format && o.t_column != "none") {
    std::size_t t_second = t_split ? t_index + 1 : kNone;
    if (t_index == kNone) {
      std::vector<std::string_view> views(names.begin(), names.end());
      Column ct("t", "--t", o.t_column, false);
      resolve(ct, views, file, used[header] + 1, false);
      t_index = ct.index;
      const auto parts = date_time_parts(o.t_column);
      if (t_index == kNone && parts) {  // the user's DATE+TIME
        Column date("t", "--t", parts->first, false);
        Column time("t", "--t", parts->second, false);
        resolve(date, views, file, used[header] + 1, false);
        resolve(time, views, file, used[header] + 1, false);
        if (date.index != kNone && time.index != kNone) {
          t_index = date.index;
          t_second = time.index;
        }
      }
    }
    const std::vector<std::string> stamps = t_index == kNone    ? std::vector<std::string>{}
                                            : t_second != kNone ? joined_cells(t_index, t_second)
                                                                : column_cells(t_index);
    if (!stamps.empty() && !std::all_of(stamps.begin(), stamps.end(),
                                        [](const std::string& c) { return is_number(c); })) {
      const std::vector<std::string_view> fmts = matching_time_formats(stamps);
      if (fmts.size() == 1) o.time_format = std::string(fmts[0]);
      if (fmts.size() > 1) {
        std::string choices;
        for (std::string_view f : fmts) choices += shell_words_sep(choices, f);
        throw DataError(file, used[first] + 1, names[t_index],
                        "the time stamps (" + show(stamps.front()) + " to " + show(stamps.back()) +
                            ") read as day/month and as month/day alike; choose with "
                            "--time-format " +
                            choices,
                        "t");
      }
    }
  }

  // What was chosen, as options; the header-row delimiter detection of "plain" is left out.
  const std::string_view hl = lines[used[header]];
  const Delimiter plain_d = detect_delimiter(hl, o.decimal);
  if (!g.delimiter && (plain_d.blanks != delim.blanks || plain_d.c != delim.c))
    read_as += " --delimiter " + shell_word(o.delimiter);
  if (!g.skip_lines && o.skip_lines) read_as += " --skip-lines " + std::to_string(o.skip_lines);
  if (!g.skip_after_header && o.skip_after_header)
    read_as += " --skip-after-header " + std::to_string(o.skip_after_header);
  if (!g.decimal && o.decimal != opt.decimal) read_as += std::string(" --decimal ") + o.decimal;
  if (!g.time_format && o.time_format != opt.time_format)
    read_as += " --time-format " + shell_word(o.time_format);
  if (!g.t && o.t_column != opt.t_column) read_as += " --t " + shell_word(o.t_column);
  if (!g.op && o.op_column != opt.op_column) read_as += " --op " + shell_word(o.op_column);
  if (!g.pv && o.pv_column != opt.pv_column) read_as += " --pv " + shell_word(o.pv_column);
  if (!g.sp && o.sp_column != opt.sp_column) read_as += " --sp " + shell_word(o.sp_column);
  if (!read_as.empty()) read_as.erase(0, 1);
  return o;
}

std::string number_problem(Num r, std::string_view cell, char decimal) {
  switch (r) {
    case Num::empty:
      return "the cell is empty (fill the gap or remove the row)";
    case Num::not_finite:
      return show(cell) + " is NaN or infinite (remove the row or fill in a measured value)";
    case Num::out_of_range:
      return show(cell) + " is out of the range of a double (fix the cell or remove the row)";
    default:
      break;
  }
  std::string p = show(cell) + " is not a number (fix the cell or remove the row";
  if (decimal == '.' && cell.find(',') != std::string_view::npos &&
      cell.find('.') == std::string_view::npos)
    p += "; for decimal commas use --decimal ,";
  else if (decimal == ',' && cell.find('.') != std::string_view::npos)
    p += "; '.' is not allowed with --decimal ,";
  return p + ")";
}

// The tag OP's and PV's columns share before their last '.' (2111FIC46005.MV, 2111FIC46005.PV),
// as historians name a loop's points; "" when they share none.
std::string loop_tag(const std::string& op, const std::string& pv) {
  const auto a = op.rfind('.'), b = pv.rfind('.');
  if (a == std::string::npos || a == 0 || a != b || op.compare(0, a, pv, 0, b) != 0) return "";
  return op.substr(0, a);
}

LoopData parse_lines(Lines& lines, const CsvOptions& opt, const std::string& file,
                     std::vector<std::string>* notes) {
  const char decimal = opt.decimal;
  if (decimal != '.' && decimal != ',')
    throw DataError(file, 0, "", "the decimal separator must be '.' or ','");
  Delimiter delim = parse_delimiter(opt.delimiter, decimal, file);
  const bool date_time = opt.time_format != "seconds" && !opt.time_format.empty();
  std::string time_format;
  if (date_time) {
    const std::string why = detail::check_time_format(opt.time_format);
    if (!why.empty())
      throw DataError(file, 0, "", "--time-format " + show(opt.time_format) + ": " + why);
    time_format = detail::expand_time_format(opt.time_format);
  }
  const bool no_time = opt.t_column == "none";
  if (opt.sample_period && !(std::isfinite(*opt.sample_period) && *opt.sample_period > 0))
    throw DataError(
        file, 0, "",
        "--sample-period must be a positive number of seconds, not " + num6g(*opt.sample_period));
  if (no_time && !opt.sample_period)
    throw DataError(file, 0, "", "without a time column (--t none) --sample-period is needed");

  if (opt.max_rows < 2)
    throw DataError(file, 0, "", "--max-rows must be at least 2 (a fit needs 2 samples)");
  const std::string_view start = lines.start();
  if (start.empty()) throw DataError(file, 0, "", "the file is empty (0 bytes)");
  // UTF-8 byte-order mark: skipped. UTF-16 would read as garbage, so it is refused early.
  if (start.substr(0, 3) == "\xEF\xBB\xBF") lines.skip(3);
  if (start.substr(0, 2) == "\xFF\xFE" || start.substr(0, 2) == "\xFE\xFF")
    throw DataError(file, 0, "", "the file is UTF-16 text; export or save it as UTF-8 (or ANSI)");

  std::string_view line;
  for (std::size_t i = 0; i < opt.skip_lines; ++i) {
    if (!lines.next(line))
      throw DataError(file, 0, "",
                      "the file has only " + std::to_string(lines.number()) +
                          " lines, but --skip-lines is " + std::to_string(opt.skip_lines));
  }
  bool have_header = false;
  while (lines.next(line)) {
    if (!blank_or_comment(line)) {
      have_header = true;
      break;
    }
  }
  if (!have_header)
    throw DataError(file, 0, "",
                    opt.skip_lines > 0
                        ? "no header row after the " + std::to_string(opt.skip_lines) +
                              " skipped lines (check --skip-lines)"
                        : "the file has no header row, only blank or comment lines");
  const std::size_t header_line = lines.number();
  if (line.find('\0') != std::string_view::npos)
    throw DataError(
        file, header_line, "",
        "the header row holds NUL bytes: the file is probably UTF-16; save it as UTF-8");
  if (delim.detect) delim = detect_delimiter(line, decimal);
  Splitter splitter(delim);

  // The names are views into the header row: kept, while a file's lines come and go.
  const std::string header(line);
  std::vector<std::string_view> names;
  switch (splitter.split(header, kNone, names)) {
    case Split::unterminated_quote:
      throw DataError(file, header_line, "", "a quoted column name has no closing quote");
    case Split::text_after_quote:
      throw DataError(file, header_line, "", "text after a closing quote in the header row");
    case Split::ok:
      break;
  }
  const bool header_numeric =
      !names.empty() && std::all_of(names.begin(), names.end(), looks_numeric);

  Column cols[] = {
      {"t", "--t", opt.t_column, !no_time},
      {"op", "--op", opt.op_column, true},
      {"pv", "--pv", opt.pv_column, true},
      {"sp", "--sp", opt.sp_column.empty() ? "sp" : opt.sp_column,
       !opt.sp_column.empty() && opt.sp_column != "none"},
      {"mv", "--mv", opt.mv_column.empty() ? "mv" : opt.mv_column,
       !opt.mv_column.empty() && opt.mv_column != "none"},
  };
  Column& ct = cols[0];
  Column& cop = cols[1];
  Column& cpv = cols[2];
  Column& csp = cols[3];
  Column& cmv = cols[4];
  // A time stamp split over two columns, date and time: --t DATE+TIME (unless one column has
  // that very name). The two cells are read as one stamp, joined by a space.
  Column ct_time("t", "--t", "", true);
  if (const auto parts = date_time_parts(opt.t_column); !no_time && parts) {
    Column whole("t", "--t", opt.t_column, false);
    resolve(whole, names, file, header_line, header_numeric);
    if (whole.index == kNone) {
      ct.spec = parts->first;
      ct_time.spec = parts->second;
      if (ct.spec.empty() || ct_time.spec.empty())
        throw DataError(file, 0, "",
                        "--t " + show(opt.t_column) +
                            ": a split time stamp is DATE+TIME, two column names or numbers");
      resolve(ct_time, names, file, header_line, header_numeric);
    }
  }
  for (Column& c : cols) {
    if (c.spec == "none" && c.role != std::string_view("t")) {
      if (c.required) throw DataError(file, 0, "", std::string(c.flag) + " cannot be 'none'");
      continue;
    }
    if (&c == &ct && no_time) continue;
    if (c.spec.empty())
      throw DataError(file, 0, "", std::string(c.flag) + " needs a column name or number");
    resolve(c, names, file, header_line, header_numeric);
  }
  std::size_t need = 0;
  for (std::size_t a = 0; a < 5; ++a) {
    if (cols[a].index == kNone) continue;
    need = std::max(need, cols[a].index + 1);
    for (std::size_t b = a + 1; b < 5; ++b)
      if (cols[b].index == cols[a].index)
        throw DataError(file, header_line, cols[a].name,
                        std::string("chosen for both ") + cols[a].role + " and " + cols[b].role +
                            " (give " + cols[b].flag + " another column)");
  }
  if (ct_time.index != kNone) {
    for (const Column& c : cols)
      if (c.index == ct_time.index)
        throw DataError(file, header_line, ct_time.name,
                        std::string("chosen for both the time of day (--t DATE+TIME) and ") +
                            (&c == &ct ? "the date" : c.role) + " (give another column)");
    need = std::max(need, ct_time.index + 1);
    ct.name += "+" + ct_time.name;  // messages name the stamp as the user gave it
  }

  for (std::size_t i = 0; i < opt.skip_after_header; ++i) {
    if (!lines.next(line))
      throw DataError(file, 0, "",
                      "the file ends before the " + std::to_string(opt.skip_after_header) +
                          " lines after the header row (check --skip-after-header)");
  }

  LoopData d;
  d.source = file;
  std::vector<std::size_t> row_line;  // file line of each sample, for later messages
  std::vector<std::string_view> cells;
  std::string numbuf;
  std::string prev_time;
  std::string first_time;
  std::string stamp;  // a split stamp's date and time, joined
  std::size_t prev_line = 0;
  detail::TimeStamp t0;
  std::string why;

  // A first data row of text (units or descriptions under the header row): the
  // --skip-after-header that skips it and the text rows after it.
  auto refuse_text_row = [&](const Column& c, std::string_view cell) {
    if (!row_line.empty() || !text_row(cells)) return;
    const std::size_t at = lines.number();
    const std::string shown = show(cell);  // the line's views end with the next line read
    std::size_t last_text = at;
    std::string_view next;
    std::vector<std::string_view> next_cells;
    for (std::size_t k = 0; k < kSniffLines && lines.next(next); ++k) {
      if (blank_or_comment(next)) continue;
      if (splitter.split(next, kNone, next_cells) != Split::ok || !text_row(next_cells)) break;
      last_text = lines.number();
    }
    throw DataError(file, at, c.name,
                    shown + " is not data: line " + std::to_string(at) +
                        " is text (units or descriptions under the header row?); skip the lines "
                        "up to " +
                        std::to_string(last_text) + " with --skip-after-header " +
                        std::to_string(last_text - header_line),
                    c.role);
  };
  // A cell that is no number, with the option that fixes the usual causes: a text row where
  // the data should start, or a date-time stamp read as seconds.
  auto number_error = [&](const Column& c, std::string_view cell, Num r) {
    const std::size_t at = lines.number();
    if (r == Num::bad || r == Num::empty) refuse_text_row(c, cell);
    if (&c == &ct && r == Num::bad) {
      const std::vector<std::string_view> fmts = matching_time_formats({std::string(cell)});
      if (!fmts.empty()) {
        std::string choices;
        for (std::string_view f : fmts) choices += shell_words_sep(choices, f);
        throw DataError(
            file, at, c.name,
            show(cell) + " is a date and time, not seconds: give --time-format " + choices, c.role);
      }
    }
    throw DataError(file, at, c.name, number_problem(r, cell, decimal), c.role);
  };
  auto cell_number = [&](const Column& c, std::vector<double>& out) {
    double v = 0;
    const Num r = parse_number(cells[c.index], decimal, numbuf, v);
    if (r != Num::ok) number_error(c, cells[c.index], r);
    if (std::abs(v) > kMaxSignalMagnitude)
      throw DataError(file, lines.number(), c.name, signal_value_problem(v, show(cells[c.index])),
                      c.role);
    out.push_back(v);
  };

  while (lines.next(line)) {
    if (blank_or_comment(line)) continue;
    if (row_line.size() >= opt.max_rows)
      throw DataError(file, lines.number(), "",
                      "more than " + std::to_string(opt.max_rows) +
                          " data rows, the --max-rows limit that keeps memory bounded (about 50 "
                          "bytes a row); give --max-rows with a larger number to read it all, "
                          "or cut the file into shorter records");
    const Split s = splitter.split(line, kNone, cells);
    if (s != Split::ok)
      throw DataError(file, lines.number(), "",
                      s == Split::unterminated_quote
                          ? "a quoted cell has no closing quote (fix the row or remove it)"
                          : "text after a closing quote (fix the row or remove it)");
    if (cells.size() < need) {
      const Column* missing = nullptr;
      for (const Column* c : {&cols[0], &cols[1], &cols[2], &cols[3], &cols[4], &ct_time})
        if (c->index != kNone && c->index >= cells.size() &&
            (missing == nullptr || c->index < missing->index))
          missing = c;
      throw DataError(file, lines.number(), missing->name,
                      "the row has only " + std::to_string(cells.size()) +
                          " cells, but this is column " + std::to_string(missing->index + 1) +
                          " (truncated row: complete it or remove it)",
                      missing->role);
    }
    // More cells than names shifts columns (an unquoted decimal comma, say): refuse it.
    for (std::size_t i = names.size(); i < cells.size(); ++i)
      if (!cells[i].empty())
        throw DataError(file, lines.number(), "",
                        "the row has " + std::to_string(cells.size()) +
                            " cells, but the header row names only " +
                            std::to_string(names.size()) + " (cell " + std::to_string(i + 1) +
                            " is " + show(cells[i]) +
                            "; a decimal comma or a delimiter inside an unquoted cell?)");
    if (ct.index != kNone) {
      std::string_view cell = cells[ct.index];
      if (ct_time.index != kNone) {
        stamp.assign(cell);
        stamp += ' ';
        stamp += cells[ct_time.index];
        cell = stamp;
      }
      double t = 0;
      if (date_time) {
        detail::TimeStamp ts;
        if (!detail::parse_time_stamp(cell, time_format, ts, why)) {
          refuse_text_row(ct, cell);
          throw DataError(file, lines.number(), ct.name,
                          show(cell) + " does not match --time-format " + show(opt.time_format) +
                              " (" + why + ")",
                          ct.role);
        }
        if (d.t.empty()) {
          t0 = ts;
          first_time.assign(cell);
          d.clock_at_zero_s = static_cast<double>(ts.seconds) + ts.fraction;
        }
        t = static_cast<double>(ts.seconds - t0.seconds) + (ts.fraction - t0.fraction);
      } else {
        const Num r = parse_number(cell, decimal, numbuf, t);
        if (r != Num::ok) number_error(ct, cell, r);
      }
      if (!d.t.empty() && !(t > d.t.back())) {
        std::string p = "time " + show(cell) + " is not after the previous row's " +
                        show(prev_time) + " (line " + std::to_string(prev_line) + "): ";
        p += t == d.t.back()
                 ? "duplicate time stamp (remove one of the rows; if the rows are evenly spaced "
                   "and only the stamps are wrong, use --t none with --sample-period)"
                 : "time goes backwards (sort the rows by time; a clock change?)";
        throw DataError(file, lines.number(), ct.name, p, ct.role);
      }
      d.t.push_back(t);
      prev_time.assign(cell);
      prev_line = lines.number();
    }
    cell_number(cop, d.op);
    cell_number(cpv, d.pv);
    if (csp.index != kNone) cell_number(csp, d.sp);
    if (cmv.index != kNone) cell_number(cmv, d.mv);
    row_line.push_back(lines.number());
  }

  const std::size_t n = row_line.size();
  if (n == 0)
    throw DataError(file, 0, "",
                    "no data rows after the header row (line " + std::to_string(header_line) + ")");
  if (n < 2)
    throw DataError(file, row_line[0], "",
                    "only 1 data row: at least 2 samples are needed (is the file complete?)");
  if (no_time) {
    d.t.resize(n);
    for (std::size_t i = 0; i < n; ++i) d.t[i] = static_cast<double>(i) * *opt.sample_period;
  }

  if (notes) {
    std::string s = "columns:";
    for (const Column& c : cols)
      if (c.index != kNone)
        s += std::string(s.back() == ':' ? " " : ", ") + c.role + " = " + show(c.name) + " (" +
             std::to_string(c.index + 1) +
             (&c == &ct && ct_time.index != kNone ? "+" + std::to_string(ct_time.index + 1) : "") +
             ")";
    if (no_time) s += "; no time column, rows " + num6g(*opt.sample_period) + " s apart";
    notes->push_back(s);
  }

  // Sampling: steps against the median step.
  std::vector<double> dt(n - 1);
  for (std::size_t i = 0; i + 1 < n; ++i) dt[i] = d.t[i + 1] - d.t[i];
  if (!std::isfinite(d.t.back() - d.t.front()))
    throw DataError(file, 0, ct.name, "the time span is too large for a double", ct.role);
  std::vector<double> sorted = dt;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2),
                   sorted.end());
  const double median = sorted[sorted.size() / 2];
  std::size_t worst = 0, irregular = 0;
  for (std::size_t i = 0; i < dt.size(); ++i) {
    const double dev = std::fabs(dt[i] - median);
    if (dev > std::fabs(dt[worst] - median)) worst = i;
    if (dev > kSamplingTolerance * median) ++irregular;
  }
  const double max_dev = std::fabs(dt[worst] - median);
  const double grid = opt.sample_period ? *opt.sample_period : median;
  const bool period_differs =
      opt.sample_period && std::fabs(*opt.sample_period - median) > kSamplingTolerance * median;

  if (!opt.resample) {
    if (irregular > 0)
      throw DataError(file, row_line[worst + 1], ct.name,
                      "irregular sampling: the step to this row is " + num6g(dt[worst]) +
                          " s, the median step is " + num6g(median) + " s (max deviation " +
                          num6g(max_dev) + " s; " + std::to_string(irregular) + " of " +
                          std::to_string(dt.size()) + " steps are more than " +
                          num6g(kSamplingTolerance * 100) +
                          " % off); use --resample to interpolate onto a uniform grid",
                      ct.role);
    if (period_differs)
      throw DataError(file, 0, ct.name,
                      "the rows are " + num6g(median) + " s apart, but --sample-period is " +
                          num6g(*opt.sample_period) +
                          " (leave it out, or add --resample to resample the data)",
                      ct.role);
  }

  if (notes && date_time)
    notes->push_back("t = 0 s is " + show(first_time) + " (line " + std::to_string(row_line[0]) +
                     "); time stamps are read as given, without time zone or daylight saving");

  // Resample whenever asked and the steps are not already uniform (to rounding).
  bool resampled = false;
  if (opt.resample && (period_differs || max_dev > 1e-9 * median)) {
    const double span = d.t.back() - d.t.front();
    const double steps = std::floor(span / grid + 1e-9);
    // More points than this comes from a wrong --sample-period, and would exhaust memory.
    const double max_points =
        std::min(kMaxGridPoints, std::max(1e6, 100.0 * static_cast<double>(n)));
    if (!(steps + 1 <= max_points))
      throw DataError(file, 0, ct.name,
                      "resampling " + num6g(span) + " s at " + num6g(grid) + " s would give " +
                          num6g(steps + 1) + " samples (choose a larger --sample-period)",
                      ct.role);
    if (steps < 1)
      throw DataError(file, 0, ct.name,
                      "the data span " + num6g(span) + " s, less than one --sample-period of " +
                          num6g(grid) + " s",
                      ct.role);
    const std::size_t m = static_cast<std::size_t>(steps) + 1;
    std::vector<double> nt(m);
    std::vector<std::size_t> seg(m);  // left sample of the interval holding each grid point
    std::vector<double> w(m);
    std::size_t j = 0;
    for (std::size_t k = 0; k < m; ++k) {
      nt[k] = d.t.front() + static_cast<double>(k) * grid;
      while (j + 2 < n && d.t[j + 1] < nt[k]) ++j;
      seg[k] = j;
      w[k] = std::clamp((nt[k] - d.t[j]) / (d.t[j + 1] - d.t[j]), 0.0, 1.0);
    }
    auto interp = [&](std::vector<double>& v, const Column& c) {
      if (v.empty()) return;
      std::vector<double> out(m);
      for (std::size_t k = 0; k < m; ++k) {
        const double a = v[seg[k]], b = v[seg[k] + 1];
        out[k] = a + w[k] * (b - a);
        if (!std::isfinite(out[k])) out[k] = (1 - w[k]) * a + w[k] * b;  // b - a overflowed
        if (!std::isfinite(out[k]))
          throw DataError(file, row_line[seg[k] + 1], c.name,
                          "values too large to interpolate (" + num6g(a) + ", " + num6g(b) + ")",
                          c.role);
      }
      v = std::move(out);
    };
    interp(d.op, cop);
    interp(d.pv, cpv);
    interp(d.sp, csp);
    interp(d.mv, cmv);
    if (notes) {
      const auto [lo, hi] = std::minmax_element(dt.begin(), dt.end());
      const std::size_t gap = static_cast<std::size_t>(hi - dt.begin());
      std::string s = "resampled " + std::to_string(n) + " rows onto a uniform " + num6g(grid) +
                      " s grid (" + (opt.sample_period ? "--sample-period" : "the median step") +
                      "): " + std::to_string(m) + " samples; the steps in the file ranged from " +
                      num6g(*lo) + " to " + num6g(*hi) + " s (largest before line " +
                      std::to_string(row_line[gap + 1]) + ")";
      if (*hi > 2 * grid) s += "; values inside gaps are interpolated, not measured";
      notes->push_back(s);
    }
    d.t = std::move(nt);
    resampled = true;
  }

  // After resampling: a coarse grid can step over the only rows where OP moves.
  const auto [op_min, op_max] = std::minmax_element(d.op.begin(), d.op.end());
  if (*op_min == *op_max)
    throw DataError(file, 0, cop.name,
                    "constant at " + num6g(*op_min) + " in all " + std::to_string(d.size()) +
                        (resampled ? " resampled samples" : " rows") +
                        ": nothing to identify (is " + cop.flag + " the controller output?)",
                    cop.role);
  d.tag = loop_tag(cop.name, cpv.name);
  return d;
}

// Format "auto": the sniffed options, and the note that shows them; an error of the reading
// then says what was sniffed, since the user gave none of it.
LoopData parse_sniffed(Lines& lines, std::string_view head, bool whole, const CsvOptions& opt,
                       const std::string& file, std::vector<std::string>* notes) {
  if (opt.format == "plain") return parse_lines(lines, opt, file, notes);
  if (opt.format != "auto")
    throw DataError(file, 0, "", "--format " + show(opt.format) + " is not 'auto' or 'plain'");
  std::string read_as;
  const CsvOptions sniffed = sniff_layout(head, whole, opt, file, read_as);
  if (read_as.empty()) return parse_lines(lines, sniffed, file, notes);
  if (notes) notes->push_back("read as " + read_as + " (found by --format auto)");
  try {
    return parse_lines(lines, sniffed, file, notes);
  } catch (const DataError& e) {
    throw DataError::rebuilt(e.file, e.line, e.column,
                             std::string(e.what()) + " [the layout found by --format auto: " +
                                 read_as + "; give options to change it]");
  }
}

}  // namespace

LoopData parse_loop_csv(std::string_view text, const CsvOptions& options,
                        const std::string& name_for_messages, std::vector<std::string>* notes) {
  Lines lines(text, name_for_messages);
  return parse_sniffed(lines, text.substr(0, kSniffBytes), text.size() <= kSniffBytes, options,
                       name_for_messages, notes);
}

LoopData read_loop_csv(const std::string& path, const CsvOptions& options,
                       std::vector<std::string>* notes) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw DataError(path, 0, "", "is a directory, not a data file (give the path of a CSV file)");
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr)
    throw DataError(
        path, 0, "",
        "cannot open the file: " + std::generic_category().message(errno) + " (check the path)");
  // Read line by line: memory follows the rows kept, not the file's size.
  const std::unique_ptr<std::FILE, int (*)(std::FILE*)> closer(f, &std::fclose);
  // The head read for sniffing is handed on to the reader, so a pipe is read once.
  std::string head(options.format == "plain" ? 0 : kSniffBytes, '\0');
  head.resize(std::fread(head.data(), 1, head.size(), f));
  if (std::ferror(f))
    throw DataError(path, 0, "",
                    "reading the file failed: " + std::generic_category().message(errno));
  const bool whole = head.size() < kSniffBytes;
  const std::string sniffed_head = options.format == "plain" ? std::string() : head;
  Lines lines(f, path, std::move(head));
  return parse_sniffed(lines, sniffed_head, whole, options, path, notes);
}

}  // namespace valvediag
