#include "valvediag/report/sweep_report.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <stdexcept>

#include "number_format.hpp"
#include "valvediag/diagnose/verdict.hpp"
#include "valvediag/report/diagnosis_report.hpp"
#include "valvediag/report/html_report.hpp"
#include "valvediag/report/json_number.hpp"

namespace valvediag {

namespace {

using nlohmann::json;

double number_of(const json& j, const char* key) {
  if (!j.contains(key) || j[key].is_null()) return LoopAssessment::kNaN;
  if (!j[key].is_number()) throw std::runtime_error(std::string("'") + key + "' must be a number");
  return j[key].get<double>();
}
std::string text_of(const json& j, const char* key) {
  if (!j.contains(key) || j[key].is_null()) return "";
  if (!j[key].is_string()) throw std::runtime_error(std::string("'") + key + "' must be a string");
  return j[key].get<std::string>();
}

std::string fmt(double v, int prec = 1) {
  return report_format::fixed(v, prec, "-");
}

// " <small>(lo-hi)</small>": the range of fs the data fit as well, when known.
std::string stiction_range_html(const LoopAssessment& a) {
  if (!std::isfinite(a.stiction_lo_percent) || !std::isfinite(a.stiction_hi_percent)) return "";
  if (a.stiction_hi_open)  // the data do not bound it from above
    return " <small title=\"fs the data fit as well (95 % profile likelihood), up to the "
           "record's OP span " +
           fmt(a.stiction_hi_percent, 2) + " %\">(&ge; " + fmt(a.stiction_lo_percent, 2) +
           ")</small>";
  return " <small title=\"fs the data fit as well (95 % profile likelihood)\">(" +
         fmt(a.stiction_lo_percent, 2) + "-" + fmt(a.stiction_hi_percent, 2) + ")</small>";
}

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string o = "\"";
  for (char c : s) o += c == '"' ? std::string("\"\"") : std::string(1, c);
  return o + "\"";
}

}  // namespace

std::string split_agreement_text(const LoopAssessment& a) {
  if (a.split_verdicts.empty()) return "-";
  const auto [agree, of] = split_agreement(a);
  return std::to_string(agree) + "/" + std::to_string(of);
}

json split_check_json(const std::vector<SplitVerdict>& splits) {
  json j = json::array();
  for (const auto& v : splits) j.push_back({{"validate", v.validate}, {"verdict", v.verdict}});
  return j;
}

json assessment_json(const LoopAssessment& a) {
  json j;
  j["loop"] = a.loop;
  j["source"] = a.source;
  j["tag"] = a.tag;
  j["verdict"] = a.verdict;
  j["reason"] = a.reason;
  j["severity"] = a.severity;
  j["stiction_percent"] = json_number(a.stiction_percent);
  j["slip_jump_percent"] = json_number(a.slip_jump_percent);
  j["stiction_lo_percent"] = json_number(a.stiction_lo_percent);
  j["stiction_hi_percent"] = json_number(a.stiction_hi_percent);
  j["stiction_hi_open"] = a.stiction_hi_open;
  j["prediction_stiction_percent"] = json_number(a.prediction_stiction_percent);
  j["model"] = a.model;
  j["fitness_percent"] = json_number(a.fitness_percent);
  j["validation_fitness_percent"] = json_number(a.validation_fitness_percent);
  j["first_missing"] = a.first_missing;
  j["analysed_from_s"] = a.analysed_from_s;
  json ladder = json::array();
  for (const auto& s : a.ladder)
    ladder.push_back({{"model", s.model},
                      {"fitness_percent", json_number(s.fitness_percent)},
                      {"validation_fitness_percent", json_number(s.validation_fitness_percent)}});
  j["ladder"] = ladder;
  const LoopHealth& h = a.health;
  j["health"] = {{"samples", h.samples},
                 {"duration_s", h.duration_s},
                 {"oscillating", h.oscillating},
                 {"period_s", json_number(h.period_s)},
                 {"regularity", json_number(h.regularity)},
                 {"amplitude", json_number(h.amplitude)},
                 {"signal", h.signal},
                 {"op_reversals_per_hour", json_number(h.op_reversals_per_hour)},
                 {"op_travel_percent_per_hour", json_number(h.op_travel_percent_per_hour)},
                 {"time_at_limits_percent", json_number(h.time_at_limits_percent)},
                 {"op_noise", json_number(h.op_noise)},
                 {"op_span_percent", json_number(h.op_span_percent)}};
  j["limit_cycle"] = limit_cycle_json(a.limit_cycle);
  j["whole_record"] = whole_record_json(a.whole_record);
  j["valve_travel"] = valve_travel_json(a.valve_travel);
  j["split_check"] = split_check_json(a.split_verdicts);
  j["elapsed_s"] = a.elapsed_s;
  j["error"] = a.error;
  j["report"] = a.report;
  return j;
}

LoopAssessment assessment_from_json(const json& j) {
  if (!j.is_object()) throw std::runtime_error("a loop's result must be a JSON object");
  LoopAssessment a;
  a.loop = text_of(j, "loop");
  if (a.loop.empty()) throw std::runtime_error("a loop's result has no 'loop' name");
  a.source = text_of(j, "source");
  a.tag = text_of(j, "tag");  // "" in older results
  a.verdict = text_of(j, "verdict");
  a.reason = text_of(j, "reason");
  a.severity = number_of(j, "severity");
  a.stiction_percent = number_of(j, "stiction_percent");
  a.slip_jump_percent = number_of(j, "slip_jump_percent");
  a.stiction_lo_percent = number_of(j, "stiction_lo_percent");  // NaN in older results
  a.stiction_hi_percent = number_of(j, "stiction_hi_percent");
  a.prediction_stiction_percent = number_of(j, "prediction_stiction_percent");  // NaN: older
  a.stiction_hi_open = j.contains("stiction_hi_open") && j["stiction_hi_open"].is_boolean() &&
                       j["stiction_hi_open"].get<bool>();
  a.model = text_of(j, "model");
  a.fitness_percent = number_of(j, "fitness_percent");
  a.validation_fitness_percent = number_of(j, "validation_fitness_percent");
  a.first_missing = text_of(j, "first_missing");
  // Results written before the quiet lead-in rule analysed the whole record.
  if (const double f = number_of(j, "analysed_from_s"); std::isfinite(f)) a.analysed_from_s = f;
  if (j.contains("ladder") && j["ladder"].is_array())
    for (const auto& s : j["ladder"])
      a.ladder.push_back({text_of(s, "model"), number_of(s, "fitness_percent"),
                          number_of(s, "validation_fitness_percent")});
  if (j.contains("health") && j["health"].is_object()) {
    const json& h = j["health"];
    LoopHealth& o = a.health;
    o.samples = static_cast<std::size_t>(std::max(0.0, number_of(h, "samples")));
    o.duration_s = number_of(h, "duration_s");
    o.oscillating = h.value("oscillating", false);
    o.period_s = number_of(h, "period_s");
    o.regularity = number_of(h, "regularity");
    o.amplitude = number_of(h, "amplitude");
    o.signal = text_of(h, "signal");
    o.op_reversals_per_hour = number_of(h, "op_reversals_per_hour");
    o.op_travel_percent_per_hour = number_of(h, "op_travel_percent_per_hour");
    o.time_at_limits_percent = number_of(h, "time_at_limits_percent");
    o.op_noise = number_of(h, "op_noise");
    o.op_span_percent = number_of(h, "op_span_percent");
  }
  if (j.contains("limit_cycle")) a.limit_cycle = limit_cycle_from_json(j["limit_cycle"]);
  if (j.contains("whole_record")) a.whole_record = whole_record_from_json(j["whole_record"]);
  if (j.contains("valve_travel")) a.valve_travel = valve_travel_from_json(j["valve_travel"]);
  if (j.contains("split_check") && j["split_check"].is_array())
    for (const auto& v : j["split_check"])
      a.split_verdicts.push_back({number_of(v, "validate"), text_of(v, "verdict")});
  a.elapsed_s = number_of(j, "elapsed_s");
  a.error = text_of(j, "error");
  a.report = text_of(j, "report");
  return a;
}

json sweep_json(const SweepInfo& info, const std::vector<LoopAssessment>& loops) {
  json j;
  j["format"] = "valvediag-sweep-1";
  j["started_utc"] = info.started_utc;
  j["finished_utc"] = info.finished_utc;
  j["source"] = info.source;
  j["shard"] = info.shard;
  j["window_s"] = info.window_s;
  j["validate"] = info.validation_fraction;
  j["elapsed_s"] = info.elapsed_s;
  json arr = json::array();
  for (const auto& a : loops) arr.push_back(assessment_json(a));
  j["loops"] = arr;
  return j;
}

std::vector<LoopAssessment> sweep_loops_from_json(const json& j) {
  if (!j.is_object() || j.value("format", "") != "valvediag-sweep-1" || !j.contains("loops") ||
      !j["loops"].is_array())
    throw std::runtime_error(
        "not a valvediag sweep results file (expected \"format\": \"valvediag-sweep-1\" and a "
        "\"loops\" array)");
  std::vector<LoopAssessment> out;
  for (std::size_t i = 0; i < j["loops"].size(); ++i) {
    try {
      out.push_back(assessment_from_json(j["loops"][i]));
    } catch (const std::exception& e) {
      throw std::runtime_error("loops[" + std::to_string(i) + "]: " + e.what());
    }
  }
  return out;
}

std::string format_sweep_table(const std::vector<LoopAssessment>& loops) {
  std::ostringstream o;
  char line[512];
  const bool checked = std::any_of(loops.begin(), loops.end(),
                                   [](const auto& a) { return !a.split_verdicts.empty(); });
  std::snprintf(line, sizeof line, "%-4s %-30s %-19s %8s %-24s %13s %-12s %9s %8s %8s %7s%s\n",
                "rank", "loop", "verdict", "stiction", "model", "fit/val %", "missing first",
                "period s", "rev/h", "travel/h", "limits", checked ? " splits" : "");
  o << line;
  std::map<std::string, int> counts;
  int rank = 0;
  for (const auto& a : loops) {
    ++counts[a.verdict];
    const std::string fit = fmt(a.fitness_percent) + "/" + fmt(a.validation_fitness_percent);
    std::string splits;
    if (checked) splits.append(" ").append(split_agreement_text(a));
    std::snprintf(line, sizeof line, "%-4d %-30s %-19s %8s %-24s %13s %-12s %9s %8s %8s %7s%s\n",
                  ++rank, a.loop.substr(0, 30).c_str(), a.verdict.c_str(),
                  (fmt(a.stiction_percent, 2)).c_str(), a.model.substr(0, 24).c_str(), fit.c_str(),
                  (a.first_missing.empty() ? "-" : a.first_missing).c_str(),
                  a.health.oscillating ? fmt(a.health.period_s, 0).c_str() : "-",
                  fmt(a.health.op_reversals_per_hour, 0).c_str(),
                  fmt(a.health.op_travel_percent_per_hour, 0).c_str(),
                  fmt(a.health.time_at_limits_percent, 0).c_str(), splits.c_str());
    o << line;
    if (a.verdict == "not-enough-data" || a.verdict == "error")
      o << "     " << (a.error.empty() ? a.reason : a.error) << "\n";
  }
  o << "verdicts:";
  for (const char* v : {"stiction", "deadband", "other-nonlinearity", "no-valve-problem",
                        "not-enough-data", "error"})
    if (counts.count(v)) o << " " << v << " " << counts[v];
  o << " (" << loops.size() << " loops)\n";
  o << "stiction: band in % of valve travel; period: of the oscillation, when one is found; "
       "travel/h: OP path in % of range per hour; limits: % of time at an OP limit\n";
  if (checked) {
    int fragile = 0;
    for (const auto& a : loops) {
      const auto [agree, of] = split_agreement(a);
      fragile += agree < of;
    }
    o << "splits: held-out shares that give the same verdict (--split-check); " << fragile
      << " loop(s) whose verdict depends on where the record is split\n";
  }
  return o.str();
}

std::string sweep_csv(const std::vector<LoopAssessment>& loops) {
  std::ostringstream o;
  o << "rank,loop,verdict,severity,stiction_percent,slip_jump_percent,model,fitness_percent,"
       "validation_fitness_percent,first_missing,oscillating,period_s,op_reversals_per_hour,"
       "op_travel_percent_per_hour,time_at_limits_percent,samples,source,reason,error,"
       "valve_travel,split_agreement,stiction_lo_percent,stiction_hi_percent,stiction_hi_open\n";
  int rank = 0;
  auto n = [](double v) { return std::isfinite(v) ? fmt(v, 4) : std::string(); };
  for (const auto& a : loops)
    o << ++rank << "," << csv_field(a.loop) << "," << a.verdict << "," << n(a.severity) << ","
      << n(a.stiction_percent) << "," << n(a.slip_jump_percent) << "," << csv_field(a.model) << ","
      << n(a.fitness_percent) << "," << n(a.validation_fitness_percent) << "," << a.first_missing
      << "," << (a.health.oscillating ? 1 : 0) << ","
      << n(a.health.oscillating ? a.health.period_s : LoopAssessment::kNaN) << ","
      << n(a.health.op_reversals_per_hour) << "," << n(a.health.op_travel_percent_per_hour) << ","
      << n(a.health.time_at_limits_percent) << "," << a.health.samples << "," << csv_field(a.source)
      << "," << csv_field(a.reason) << "," << csv_field(a.error) << ","
      << (a.valve_travel.decided ? a.valve_travel.verdict : "") << ","
      << (a.split_verdicts.empty() ? "" : split_agreement_text(a)) << ","
      << n(a.stiction_lo_percent) << "," << n(a.stiction_hi_percent) << ","
      << (std::isfinite(a.stiction_hi_percent) ? (a.stiction_hi_open ? "1" : "0") : "") << "\n";
  return o.str();
}

// The loops in rank order as horizontal bars of their severity (the ranking key, 0-10),
// coloured by verdict, named by tag: which valves to look at first, at a glance. Inline SVG,
// so the page needs nothing else to show it.
std::string severity_chart(const std::vector<LoopAssessment>& loops) {
  constexpr std::size_t kMaxBars = 40;
  constexpr int kLabel = 230, kBars = 520, kRow = 17, kTop = 22, kMax = 10;
  const std::size_t n = std::min(loops.size(), kMaxBars);
  if (n == 0) return "";
  const int height = kTop + static_cast<int>(n) * kRow + 6;
  const int width = kLabel + kBars + 190;
  auto colour = [](const std::string& v) {
    return v == "stiction"             ? "#d9534f"
           : v == "deadband"           ? "#e8923a"
           : v == "other-nonlinearity" ? "#d4c140"
           : v == "no-valve-problem"   ? "#7fa7d9"
                                       : "#bbbbbb";
  };
  std::ostringstream o;
  o << "<figure id=\"severity-chart\"><svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width
    << "\" height=\"" << height << "\" viewBox=\"0 0 " << width << " " << height
    << "\" font-family=\"sans-serif\" font-size=\"12\" role=\"img\" "
       "aria-label=\"severity of each loop, worst first\">\n";
  for (int k = 0; k <= kMax; k += 2) {
    const int x = kLabel + kBars * k / kMax;
    o << "<line x1=\"" << x << "\" y1=\"" << kTop - 4 << "\" x2=\"" << x << "\" y2=\"" << height - 4
      << "\" stroke=\"#dddddd\"/><text x=\"" << x << "\" y=\"" << kTop - 8
      << "\" text-anchor=\"middle\" fill=\"#555555\">" << k << "</text>\n";
  }
  for (std::size_t i = 0; i < n; ++i) {
    const LoopAssessment& a = loops[i];
    const int y = kTop + static_cast<int>(i) * kRow;
    std::string name = a.tag.empty() ? a.loop : a.tag;
    if (name.size() > 34) {
      name.resize(33);
      name.push_back('~');
    }
    o << "<text x=\"" << kLabel - 6 << "\" y=\"" << y + 12 << "\" text-anchor=\"end\">"
      << html_escape(name) << "</text>";
    const double s = std::clamp(a.severity, 0.0, static_cast<double>(kMax));
    const int w = static_cast<int>(std::lround(kBars * s / kMax));
    if (a.severity >= 0)
      o << "<rect x=\"" << kLabel << "\" y=\"" << y + 2 << "\" width=\"" << std::max(w, 1)
        << "\" height=\"" << kRow - 4 << "\" fill=\"" << colour(a.verdict) << "\"/>";
    std::string what = a.verdict;
    if (std::isfinite(a.stiction_percent))
      what.append(" ").append(fmt(a.stiction_percent, 2)).append(" %");
    o << "<text x=\"" << kLabel + std::max(w, 0) + 5 << "\" y=\"" << y + 12
      << "\" fill=\"#333333\">" << html_escape(what) << "</text>\n";
  }
  o << "</svg><figcaption>Severity, the ranking key: the verdict (stiction 6, deadband 5, other "
       "nonlinearity 3, no valve problem 1, not enough data 0), 1 more when the loop oscillates, "
       "and half the stiction band in % of travel (at most 3). The label gives the verdict and "
       "the band.";
  if (loops.size() > n)
    o << " The " << n << " worst of " << loops.size() << " loops; the table lists all.";
  o << "</figcaption></figure>\n";
  return o.str();
}

std::string sweep_html(const SweepInfo& info, const std::vector<LoopAssessment>& loops,
                       const std::vector<std::string>& report_links) {
  std::ostringstream o;
  o << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
       "<title>valvediag sweep</title><style>"
       "body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse}"
       "td,th{border:1px solid #bbb;padding:.25em .5em;text-align:right}"
       "td.l,th.l{text-align:left}tr.stiction{background:#fdd}tr.deadband{background:#fed}"
       "tr.other-nonlinearity{background:#ffe}tr.error,tr.not-enough-data{color:#777}"
       "table.counts{margin-bottom:1em;max-width:60em}table.counts td.l{white-space:normal}"
       "div.wide{overflow-x:auto;max-width:100%}div.wide table{font-size:.9em}"
       "td.v,table.counts td:first-child{white-space:nowrap}small{word-break:break-all;color:#555}"
       "figure{margin:0 0 1em 0}figcaption{font-size:.85em;color:#555;max-width:60em}"
       "</style></head><body>\n";
  o << "<h1>Valve diagnostic sweep</h1>\n<p>" << html_escape(info.source) << "; started "
    << html_escape(info.started_utc) << ", finished " << html_escape(info.finished_utc);
  if (!info.shard.empty()) o << "; shard " << html_escape(info.shard);
  o << "; " << loops.size() << " loops, ranked by severity.</p>\n";
  // How many of each verdict, and what each asks of the engineer.
  std::map<std::string, int> counts;
  for (const auto& a : loops) ++counts[a.verdict];
  o << "<table class=\"counts\"><tr><th class=\"l\">verdict</th><th>loops</th>"
       "<th class=\"l\">what it means, what to do</th></tr>\n";
  for (const char* v : {"stiction", "deadband", "other-nonlinearity", "no-valve-problem",
                        "not-enough-data", "error"})
    if (counts.count(v))
      o << "<tr class=\"" << v << "\"><td class=\"l\">" << v << "</td><td>" << counts[v]
        << "</td><td class=\"l\">" << html_escape(verdict_advice(v)) << "</td></tr>\n";
  o << "</table>\n";
  o << severity_chart(loops);
  // Wide: it scrolls inside its box rather than widening the page.
  o << "<div class=\"wide\"><table><tr><th>rank</th><th class=\"l\">loop</th><th "
       "class=\"l\">verdict</th>"
       "<th>stiction % travel</th><th>slip jump %</th><th class=\"l\">model</th><th>fitness "
       "%</th><th>validation %</th><th class=\"l\">missing first</th><th>oscillation period "
       "s</th><th>OP reversals/h</th><th>OP travel %/h</th><th>time at limits %</th>"
       "<th>same verdict at splits</th><th class=\"l\">note</th></tr>\n";
  for (std::size_t i = 0; i < loops.size(); ++i) {
    const auto& a = loops[i];
    const std::string link = i < report_links.size() ? report_links[i] : "";
    o << "<tr class=\"" << html_escape(a.verdict) << "\"><td>" << i + 1 << "</td><td class=\"l\">";
    // The tag the data names, when it does, with the file's name under it.
    const bool tagged = !a.tag.empty() && a.tag != a.loop;
    const std::string name = html_escape(tagged ? a.tag : a.loop);
    if (!link.empty())
      o << "<a href=\"" << html_escape(link) << "\">" << name << "</a>";
    else
      o << name;
    if (tagged) o << "<br><small>" << html_escape(a.loop) << "</small>";
    o << "</td><td class=\"l v\">" << html_escape(a.verdict) << "</td><td>"
      << fmt(a.stiction_percent, 2) << stiction_range_html(a) << "</td><td>"
      << fmt(a.slip_jump_percent, 2) << "</td>"
      << "<td class=\"l\">" << html_escape(a.model) << "</td><td>" << fmt(a.fitness_percent)
      << "</td><td>" << fmt(a.validation_fitness_percent) << "</td><td class=\"l\">"
      << html_escape(a.first_missing) << "</td><td>"
      << (a.health.oscillating ? fmt(a.health.period_s, 0) : "-") << "</td><td>"
      << fmt(a.health.op_reversals_per_hour, 0) << "</td><td>"
      << fmt(a.health.op_travel_percent_per_hour, 0) << "</td><td>"
      << fmt(a.health.time_at_limits_percent, 0) << "</td><td>" << split_agreement_text(a)
      << "</td><td class=\"l\">"
      << html_escape(a.error.empty() ? (a.verdict == "not-enough-data" ? a.reason : "") : a.error)
      << "</td></tr>\n";
  }
  o << "</table></div>\n</body></html>\n";
  return o.str();
}

}  // namespace valvediag
