// The randomized benchmark of the diagnosis (scripts/accuracy.sh): a development range and a
// test range of seeds, each case a drawn loop with hidden effects (random_loop.hpp), diagnosed
// from its start model. Prints one line per case as it finishes, then per range the tables
// (named first, top two, gain >= 2, parameter errors, false findings on controls, confusion),
// then both ranges side by side.
//
//   valvediag_accuracy [--dev FIRST:COUNT] [--test FIRST:COUNT] [--only CATEGORY] [--jobs N]
//                      [--json FILE]   (every case's findings with their statistics)
//   valvediag_accuracy --plant SWEEP.json   (a sweep of ../shared/data/plant-loops: verdicts
//                                            against the labels, per file and per valve tag)
//
// Develop on the development seeds; only ever run the test seeds.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "valvediag/core/parallel_for.hpp"
#include "valvediag/diagnose/diagnosis_benchmark.hpp"
#include "valvediag/report/json_number.hpp"
#include "valvediag/util/text_stats.hpp"

using namespace valvediag;

namespace {

struct Range {
  std::uint64_t first = 0, count = 0;
};

Range parse_range(const std::string& s) {
  const auto colon = s.find(':');
  if (colon == std::string::npos) throw std::invalid_argument("a range is FIRST:COUNT, got " + s);
  return {std::stoull(s.substr(0, colon)), std::stoull(s.substr(colon + 1))};
}

std::string case_line(const BenchmarkOutcome& o) {
  std::string hidden(o.loop.hidden.empty() ? "-" : "");
  for (const auto& h : o.loop.hidden) {
    if (!hidden.empty()) hidden.push_back('+');
    hidden.append(h);
  }
  std::string ranked;
  for (std::size_t i = 0; i < o.ranked.size() && i < 3; ++i) {
    if (i) ranked += ' ';
    ranked += o.ranked[i];
    if (o.supported[i]) ranked += '*';
  }
  std::string errs;
  for (const auto& e : o.errors)
    errs += strprintf(" %s %.3g/%.3g", e.name.c_str(), e.estimate, e.truth);
  if (o.climbed) errs += " | --auto: " + o.climbed_model;
  const char* mark = o.loop.hidden.empty() ? (o.false_alarm ? "ALARM" : "ok")
                     : o.named_first       ? "FIRST"
                     : o.top_two           ? "top2"
                                           : "miss";
  return strprintf(
      "%7llu %-15s %-22s start %-22s %-5s gain %+7.1f (held out %+8.1f) | %s |%s | %.1f s%s |%s\n",
      static_cast<unsigned long long>(o.loop.seed), o.loop.category.c_str(), hidden.c_str(),
      o.loop.start_model.c_str(), mark, o.true_gain, o.true_validation_gain, ranked.c_str(),
      errs.c_str(), o.seconds, o.error.empty() ? "" : (" ERROR " + o.error).c_str(),
      o.detail.c_str());
}

std::vector<BenchmarkOutcome> run_range(const Range& r, const std::string& only, int jobs,
                                        const char* label) {
  std::vector<std::uint64_t> seeds;
  for (std::uint64_t s = r.first; s < r.first + r.count; ++s) {
    const auto cat = benchmark_categories(s, 1).front();
    if (only.empty() || cat == only) seeds.push_back(s);
  }
  std::vector<BenchmarkOutcome> out(seeds.size());
  std::mutex m;
  DiagnoseOptions opt;
  opt.fit.threads = 1;  // the cases share the cores
  parallel_for(seeds.size(), worker_count(jobs, seeds.size()), [&](unsigned, std::size_t i) {
    const std::uint64_t seed = seeds[i];
    const std::string cat = benchmark_categories(seed, 1).front();
    BenchmarkOutcome o;
    try {
      o = run_benchmark_case(draw_random_loop(seed, cat), opt, /*climb=*/true);
    } catch (const std::exception& e) {
      o.loop.seed = seed;
      o.loop.category = cat;
      o.error = e.what();
    }
    const std::lock_guard<std::mutex> lock(m);
    std::printf("%s %s", label, case_line(o).c_str());
    std::fflush(stdout);
    out[i] = std::move(o);
  });
  return out;
}

// The plant sweep against the provider's labels (the folder: stiction/ or no-stiction/): per file,
// and per valve tag with each tag counted once (the share of its records called sticky), since
// one valve recorded on many days is one piece of evidence.
// The valve's tag of a plant file "stic_TAG_DATE_TIME_Stick1=...": the files of one valve on
// other days share it. (No std::regex: GCC 12 warns inside <regex> under the sanitizers.)
std::string valve_tag(const std::string& file) {
  const std::string prefix = "stic_";
  const std::size_t end = file.find("_Stick1=");
  if (file.rfind(prefix, 0) != 0 || end == std::string::npos) return file;
  std::string stem = file.substr(prefix.size(), end - prefix.size());
  for (int field = 0; field < 2; ++field) {  // drop DATE and TIME
    const std::size_t cut = stem.find_last_of('_');
    if (cut == std::string::npos) return file;
    stem.resize(cut);
  }
  return stem;
}

int plant_report(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    std::fprintf(stderr, "error: cannot read %s\n", path.c_str());
    return 2;
  }
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  if (j.is_discarded() || !j.contains("loops")) {
    std::fprintf(stderr, "error: %s is not a sweep's JSON\n", path.c_str());
    return 2;
  }
  std::map<std::string, std::map<std::string, int>> table;  // label -> verdict -> files
  struct Tag {
    bool sticky = false;
    int files = 0, called = 0;
  };
  std::map<std::string, Tag> tags;
  for (const auto& l : j["loops"]) {
    const std::string src = l.value("source", "");
    const bool sticky = src.find("/no-stiction/") == std::string::npos;
    const std::string v = l.value("verdict", "");
    table[sticky ? "stiction" : "no-stiction"][v]++;
    const std::string tag = valve_tag(src.substr(src.find_last_of('/') + 1));
    Tag& t = tags[tag];
    t.sticky = sticky;
    ++t.files;
    t.called += v == "stiction";
  }
  std::printf("%-12s", "label");
  const char* verdicts[] = {"stiction",         "deadband",        "other-nonlinearity",
                            "no-valve-problem", "not-enough-data", "error"};
  for (const char* v : verdicts) std::printf(" %18s", v);
  std::printf("\n");
  for (const char* label : {"stiction", "no-stiction"}) {
    std::printf("%-12s", label);
    for (const char* v : verdicts) std::printf(" %18d", table[label][v]);
    std::printf("\n");
  }
  auto total = [&](const char* label) {
    int n = 0;
    for (const auto& [v, c] : table[label]) n += c;
    return n;
  };
  const double found = table["stiction"]["stiction"] / static_cast<double>(total("stiction"));
  const double kept =
      1.0 - table["no-stiction"]["stiction"] / static_cast<double>(total("no-stiction"));
  std::printf(
      "per file: balanced accuracy %.1f %% (sticky found %d/%d, clean called sticky %d/%d)\n",
      50 * (found + kept), table["stiction"]["stiction"], total("stiction"),
      table["no-stiction"]["stiction"], total("no-stiction"));
  double f = 0.0, k = 0.0;
  int ns = 0, nc = 0;
  for (const auto& [tag, t] : tags) {
    const double share = static_cast<double>(t.called) / t.files;
    if (t.sticky) {
      f += share;
      ++ns;
    } else {
      k += 1.0 - share;
      ++nc;
    }
  }
  std::printf(
      "per valve tag (each tag once): balanced accuracy %.1f %% (%d sticky tags, %d clean)\n",
      50 * (f / std::max(ns, 1) + k / std::max(nc, 1)), ns, nc);
  for (const auto& [tag, t] : tags)
    std::printf("  %-28s %-8s %d of %d called stiction\n", tag.c_str(),
                t.sticky ? "sticky" : "clean", t.called, t.files);
  return 0;
}

// Each case with every finding's statistics, to study a ranking without running the fits again.
nlohmann::json outcomes_json(const std::vector<BenchmarkOutcome>& outcomes, const char* range) {
  nlohmann::json cases = nlohmann::json::array();
  for (const auto& o : outcomes) {
    nlohmann::json findings = nlohmann::json::array();
    for (const auto& f : o.findings)
      findings.push_back(
          {{"effect", f.effect},
           {"estimation_gain_percent", json_number(f.estimation_gain_percent)},
           {"validation_gain_percent", json_number(f.validation_gain_percent)},
           {"gain_percent", json_number(f.gain_percent)},
           {"score", json_number(f.score)},
           {"evidence", json_number(f.evidence)},
           {"evidence_test", f.evidence_test},
           {"supported", f.supported},
           {"parameter_count", json_number(f.parameter_count)},
           {"output_bic_change", json_number(f.output_bic_change)},
           {"validation_deviance_change", json_number(f.validation_deviance_change)},
           {"prediction_bic_change", json_number(f.prediction_bic_change)},
           {"prediction_validation_deviance_change",
            json_number(f.prediction_validation_deviance_change)},
           {"prediction_drift_bic_change", json_number(f.prediction_drift_bic_change)},
           {"prediction_estimation_gain_percent",
            json_number(f.prediction_estimation_gain_percent)},
           {"prediction_validation_gain_percent",
            json_number(f.prediction_validation_gain_percent)},
           {"indistinguishable_from", f.indistinguishable_from}});
    nlohmann::json tests = nlohmann::json::array();
    for (const auto& t : o.residual_tests)
      tests.push_back({{"name", t.name},
                       {"statistic", json_number(t.statistic)},
                       {"score", json_number(t.score)}});
    cases.push_back(
        {{"range", range},
         {"residual_tests", tests},
         {"seed", o.loop.seed},
         {"category", o.loop.category},
         {"hidden", o.loop.hidden},
         {"start_model", o.loop.start_model},
         {"error", o.error},
         {"judge_horizon", o.judge.horizon},
         {"samples", o.samples},
         {"estimation_end", o.estimation_end},
         {"model_fitness_percent", json_number(o.judge.model_fitness_percent)},
         {"model_validation_fitness_percent",
          json_number(o.judge.model_validation_fitness_percent)},
         {"true_model_gain_percent", json_number(o.true_model_gain)},
         {"valve_search_shortfall_points", json_number(o.valve_search_shortfall)},
         {"climbed_model", o.climbed ? nlohmann::json(o.climbed_model) : nlohmann::json()},
         {"findings", findings}});
  }
  return cases;
}

}  // namespace

int main(int argc, char** argv) {
  Range dev{0, 156}, test{1000000, 156};
  std::string only, json_path;
  int jobs = 0;
  bool run_dev = true, run_test = true;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      auto value = [&]() -> std::string {
        if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
        return argv[++i];
      };
      if (a == "--plant") return plant_report(value());
      if (a == "--dev")
        dev = parse_range(value());
      else if (a == "--test")
        test = parse_range(value());
      else if (a == "--dev-only")
        run_test = false;
      else if (a == "--test-only")
        run_dev = false;
      else if (a == "--only")
        only = value();
      else if (a == "--jobs")
        jobs = std::stoi(value());
      else if (a == "--json")
        json_path = value();
      else
        throw std::invalid_argument("unknown argument " + a +
                                    " (--dev FIRST:COUNT, --test FIRST:COUNT, --dev-only, "
                                    "--test-only, --only CATEGORY, --jobs N, --json FILE)");
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  }
  std::vector<BenchmarkOutcome> d, t;
  if (run_dev) d = run_range(dev, only, jobs, "dev ");
  if (run_test) t = run_range(test, only, jobs, "test");
  if (run_dev)
    std::printf(
        "\n%s",
        format_benchmark(d, strprintf("== development seeds %llu..%llu",
                                      static_cast<unsigned long long>(dev.first),
                                      static_cast<unsigned long long>(dev.first + dev.count - 1)))
            .c_str());
  if (run_test)
    std::printf(
        "\n%s",
        format_benchmark(
            t, strprintf("== test seeds %llu..%llu", static_cast<unsigned long long>(test.first),
                         static_cast<unsigned long long>(test.first + test.count - 1)))
            .c_str());
  if (run_dev && run_test) std::printf("\n%s", format_benchmark_pair(d, t).c_str());
  if (!json_path.empty()) {
    nlohmann::json all = outcomes_json(d, "dev");
    for (auto& c : outcomes_json(t, "test")) all.push_back(std::move(c));
    std::ofstream out(json_path);
    out << all.dump(1) << '\n';
    if (!out) {
      std::fprintf(stderr, "error: cannot write %s\n", json_path.c_str());
      return 1;
    }
  }
  return 0;
}
