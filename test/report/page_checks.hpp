// Checks shared by the report tests: one self-contained HTML page, and each plot in it.
#pragma once

#include <doctest/doctest.h>

#include <map>
#include <string>

namespace report_test {

// The text of <figure id="ID" ...> ... </figure>, empty when there is none.
inline std::string figure(const std::string& html, const std::string& id) {
  const auto b = html.find("<figure id=\"" + id + "\"");
  if (b == std::string::npos) return "";
  const auto e = html.find("</figure>", b);
  return e == std::string::npos ? "" : html.substr(b, e - b);
}

// A plot: an inline SVG with drawn data paths.
inline bool has_plot(const std::string& html, const std::string& id) {
  const std::string f = figure(html, id);
  return f.find("<svg") != std::string::npos && f.find("</svg>") != std::string::npos &&
         f.find(" d='M") != std::string::npos;
}

inline bool has(const std::string& s, const std::string& what) {
  return s.find(what) != std::string::npos;
}

inline std::size_t count(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (auto p = s.find(what); p != std::string::npos; p = s.find(what, p + 1)) ++n;
  return n;
}

// One HTML document that needs nothing else: no scripts, no src=, every href an in-page
// reference, the only URLs the SVG namespace names, ids unique across the inlined SVGs.
inline void check_self_contained(const std::string& html) {
  CHECK(html.rfind("<!DOCTYPE html>", 0) == 0);
  CHECK(html.find("</html>") != std::string::npos);
  CHECK(html.find("<script") == std::string::npos);
  CHECK(html.find("src=") == std::string::npos);
  CHECK(html.find("<?xml") == std::string::npos);
  CHECK(html.find("<link") == std::string::npos);
  CHECK(html.find("@import") == std::string::npos);
  for (auto p = html.find("href="); p != std::string::npos; p = html.find("href=", p + 1))
    CHECK_MESSAGE(html[p + 6] == '#', html.substr(p, 40));
  for (auto p = html.find("http"); p != std::string::npos; p = html.find("http", p + 1)) {
    const std::string url = html.substr(p, 30);
    CHECK_MESSAGE((url.rfind("http://www.w3.org/2000/svg", 0) == 0 ||
                   url.rfind("http://www.w3.org/1999/xlink", 0) == 0),
                  url);
  }
  std::map<std::string, int> ids;
  for (const char* pat : {" id=\"", " id='"}) {
    for (auto p = html.find(pat); p != std::string::npos; p = html.find(pat, p + 1)) {
      const char q = pat[4];
      const auto e = html.find(q, p + 5);
      ++ids[html.substr(p + 5, e - p - 5)];
    }
  }
  for (const auto& [id, n] : ids) CHECK_MESSAGE(n == 1, "duplicate id " << id);
}

}  // namespace report_test
