#include "valvediag/diagnose/diagnosis_benchmark.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <stdexcept>

#include "valvediag/diagnose/prediction_refit.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag {

namespace {

bool contains(const std::vector<std::string>& v, const std::string& s) {
  return std::find(v.begin(), v.end(), s) != v.end();
}

double named(const std::vector<NamedValue>& p, const char* name) {
  for (const auto& v : p)
    if (v.name == name) return v.value;
  return std::nan("");
}

// The fitted figure comparable with a true one (TrueParameter's names and units).
double estimate_of(const TrueParameter& t, const std::vector<NamedValue>& p) {
  if (t.name == "band") {
    for (const char* n : {"fs", "S", "d"})
      if (const double v = named(p, n); std::isfinite(v)) return v;
    return std::nan("");
  }
  if (t.name == "limit") {  // the nearer of the two fitted limits
    const double lo = named(p, "lower"), hi = named(p, "upper");
    if (!std::isfinite(lo) || !std::isfinite(hi)) return std::nan("");
    return std::abs(lo - t.value) < std::abs(hi - t.value) ? lo : hi;
  }
  if (t.name == "mild_band") return named(p, "fs_mild");
  if (t.name == "log_rangeability") return named(p, "curvature");
  if (t.name == "tau") return named(p, "tau");
  if (t.name == "dead_time") return named(p, "dead_time");
  if (t.name == "rate_gain") return named(p, "rate_gain");
  return std::nan("");
}

}  // namespace

std::vector<std::string> benchmark_categories(std::uint64_t first_seed, std::uint64_t count) {
  const auto& c = random_loop_categories();
  std::vector<std::string> out;
  for (std::uint64_t s = first_seed; s < first_seed + count; ++s) out.push_back(c[s % c.size()]);
  return out;
}

BenchmarkOutcome run_benchmark_case(const RandomLoop& loop, DiagnoseOptions opt, bool climb) {
  BenchmarkOutcome o;
  o.loop = loop;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    const ScenarioRun run = run_scenario_traced(loop.scenario, loop.noise_seed, loop.samples);
    const LoopData& d = run.data;
    opt.validation_fraction = loop.validation_fraction;
    const Diagnosis dg =
        diagnose(d.op, d.pv, d.sample_period(), parse_model_spec(loop.start_model), opt);
    const auto& f = dg.last().findings;
    o.findings = f;
    o.judge = dg.last().judge;
    o.residual_tests = dg.last().residual.tests;
    o.samples = d.pv.size();
    o.estimation_end = dg.last().fit.estimation_end;
    if (o.judge.horizon == 0) {
      o.judge.model_fitness_percent = dg.last().fit.fitness_percent;
      o.judge.model_validation_fitness_percent = dg.last().fit.validation_fitness_percent;
    }
    for (const auto& x : f)
      o.detail += strprintf(" %s:%.2f/%.2f/%.0f/%.3f", x.effect.c_str(), x.estimation_gain_percent,
                            x.validation_gain_percent, x.prediction_bic_change,
                            x.prediction_validation_gain_percent);
    for (const auto& x : f) {
      o.ranked.push_back(x.effect);
      o.supported.push_back(x.supported);
    }
    if (!f.empty()) o.first = f.front().effect;
    const auto& hidden = loop.hidden;
    if (hidden.empty()) {
      for (const auto& x : f)
        if (x.supported) {
          o.false_alarm = true;
          o.false_effect = x.effect;
          break;
        }
    } else {
      o.named_first = contains(hidden, o.first);
      o.top_two = true;
      const std::size_t top = std::max<std::size_t>(2, hidden.size());
      for (const auto& h : hidden) {
        const auto it = std::find(o.ranked.begin(), o.ranked.end(), h);
        o.top_two = o.top_two && it != o.ranked.end() &&
                    static_cast<std::size_t>(it - o.ranked.begin()) < top;
      }
      // The gain and the figures of the hidden effects' trials (the first hidden effect's gain).
      bool first = true;
      for (const auto& h : hidden) {
        for (const auto& x : f) {
          if (x.effect != h) continue;
          if (first) {
            o.true_gain = x.gain_percent;
            o.true_validation_gain = x.validation_gain_percent;
            o.true_supported = x.supported;
            first = false;
          }
          for (const auto& t : loop.truth)
            if (t.effect == h) {
              const double est = estimate_of(t, x.parameters);
              const double refit = !refitted_to_prediction(h) ? std::nan("")
                                   : x.prediction_parameters.empty()
                                       ? est
                                       : estimate_of(t, x.prediction_parameters);
              o.errors.push_back({h, t.name, t.value, est, refit});
            }
        }
      }
      o.gains = o.true_gain >= 2.0;
      const ModelFit& m = dg.last().fit;
      const std::size_t N = d.pv.size(), e0 = m.estimation_end;
      if (o.judge.horizon == 0 && !contains(hidden, "disturbance") && run.valve_pv.size() == N &&
          m.first_sample + 1 < e0 && e0 + 1 < N)
        o.true_model_gain =
            std::min(fitness_percent(d.pv, run.valve_pv, m.first_sample, e0) - m.fitness_percent,
                     fitness_percent(d.pv, run.valve_pv, e0, N) - m.validation_fitness_percent);
      const bool one_valve = hidden.size() == 1 && is_valve_effect(hidden.front());
      const auto tf = std::find_if(f.begin(), f.end(), [&](const Finding& x) {
        return one_valve && x.effect == hidden.front();
      });
      if (o.judge.horizon == 0 && one_valve && d.mv.size() == N && tf != f.end() &&
          std::isfinite(tf->trial_fitness_percent)) {
        // The trial's process part: its chain less the valve effects (still canonical).
        ModelSpec process = tf->trial_spec;
        std::erase_if(process.effects, [](const EffectSpec& e) { return is_valve_effect(e.name); });
        const ModelFit on_x = fit_model(d.mv, d.pv, d.sample_period(), process, fit_options(opt));
        if (std::isfinite(on_x.fitness_percent))
          o.valve_search_shortfall = on_x.fitness_percent - tf->trial_fitness_percent;
      }
      if (climb && hidden.size() >= 2) {
        const ModelSpec reached = verdict_model(
            diagnose_auto(d.op, d.pv, d.sample_period(), parse_model_spec(loop.start_model), opt));
        o.climbed = true;
        o.climbed_model = to_string(reached);
        for (const auto& h : hidden) o.climb_found += reached.has(h);
      }
    }
  } catch (const std::exception& e) {
    o.error = e.what();
  }
  o.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return o;
}

namespace {

struct Tally {
  int cases = 0, first = 0, top2 = 0, gains = 0, supported = 0, alarms = 0, errors = 0;
  int climbed = 0, climb_all = 0, climb_some = 0;  // cases climbed; all or some hidden added
  // Cases whose true model's gain was measured, those where it reaches 2 points, and of those
  // the cases where adding the hidden effect did.
  int measured = 0, reachable = 0, reached = 0;
  // Cases where the trial gained under 2 points and the valve search was measured
  // (BenchmarkOutcome::valve_search_shortfall), and of those where the true valve position fits
  // the estimation part 1 point or more better than the search's valve.
  int missed_searched = 0, search_short = 0;
  std::map<std::string, std::vector<double>> abs_err, rel_err;              // per parameter name
  std::map<std::string, std::vector<double>> refit_abs_err, refit_rel_err;  // of the refits
  double seconds = 0.0;
  void add(const BenchmarkOutcome& o) {
    ++cases;
    seconds += o.seconds;
    if (!o.error.empty()) {
      ++errors;
      return;
    }
    first += o.named_first;
    top2 += o.top_two;
    gains += o.gains;
    if (std::isfinite(o.true_model_gain)) {
      ++measured;
      reachable += o.true_model_gain >= 2.0;
      reached += o.true_model_gain >= 2.0 && o.gains;
    }
    if (!o.gains && std::isfinite(o.valve_search_shortfall)) {
      ++missed_searched;
      search_short += o.valve_search_shortfall >= 1.0;
    }
    supported += o.true_supported;
    alarms += o.false_alarm;
    climbed += o.climbed;
    climb_all += o.climbed && o.climb_found == o.loop.hidden.size();
    climb_some += o.climbed && o.climb_found > 0;
    for (const auto& e : o.errors) {
      if (!std::isfinite(e.estimate)) continue;
      abs_err[e.name].push_back(std::abs(e.estimate - e.truth));
      if (e.truth != 0)
        rel_err[e.name].push_back(std::abs(e.estimate - e.truth) / std::abs(e.truth));
      if (!std::isfinite(e.refit)) continue;
      refit_abs_err[e.name].push_back(std::abs(e.refit - e.truth));
      if (e.truth != 0)
        refit_rel_err[e.name].push_back(std::abs(e.refit - e.truth) / std::abs(e.truth));
    }
  }
};

std::string pct(int n, int of) {
  return of > 0 ? strprintf("%3d/%-3d %3.0f%%", n, of, 100.0 * n / of)
                : std::string("    -       ");
}

std::string category_of(const BenchmarkOutcome& o) {
  return o.loop.category.empty() ? "?" : o.loop.category;
}

std::map<std::string, Tally> tally(const std::vector<BenchmarkOutcome>& v, Tally& all,
                                   Tally& fair) {
  std::map<std::string, Tally> t;
  for (const auto& o : v) {
    t[category_of(o)].add(o);
    all.add(o);
    if (!o.loop.hidden.empty()) fair.add(o);
  }
  return t;
}

std::string errors_text(const Tally& t) {
  std::string s;
  const auto rel_median = [](const auto& m, const std::string& name) {
    const auto it = m.find(name);
    return it == m.end() || it->second.empty() ? std::nan("") : 100 * median(it->second);
  };
  for (const auto& [name, v] : t.abs_err) {
    s += strprintf("%s%s: median |err| %.3g (%.0f %%)", s.empty() ? "" : "; ", name.c_str(),
                   median(v), rel_median(t.rel_err, name));
    if (const auto r = t.refit_abs_err.find(name); r != t.refit_abs_err.end() && !r->second.empty())
      s += strprintf(", refitted %.3g (%.0f %%)", median(r->second),
                     rel_median(t.refit_rel_err, name));
  }
  return s;
}

}  // namespace

std::string format_benchmark(const std::vector<BenchmarkOutcome>& outcomes,
                             const std::string& title) {
  Tally all, fair;
  const auto t = tally(outcomes, all, fair);
  std::string s = title + "\n";
  // "true >= 2": of the cases measured, where the true model gains 2 points over the start
  // model (BenchmarkOutcome::true_model_gain); "gain there": of those, where the trial did;
  // "search short": of the valve effects' trials that gained under 2 points, where the true
  // valve position fits the estimation part 1 point better (valve_search_shortfall).
  s += strprintf("%-15s %-13s %-13s %-13s %-13s %-13s %-13s %-13s %s\n", "hidden", "named first",
                 "top two", "gain >= 2", "supported", "true >= 2", "gain there", "search short",
                 "parameter error (fitted against true)");
  for (const auto& c : random_loop_categories()) {
    if (!t.count(c) || c == "none") continue;
    const Tally& x = t.at(c);
    const int n = x.cases - x.errors;
    s += strprintf("%-15s %s %s %s %s %s %s %s %s%s\n", c.c_str(), pct(x.first, n).c_str(),
                   pct(x.top2, n).c_str(), pct(x.gains, n).c_str(), pct(x.supported, n).c_str(),
                   pct(x.reachable, x.measured).c_str(), pct(x.reached, x.reachable).c_str(),
                   pct(x.search_short, x.missed_searched).c_str(), errors_text(x).c_str(),
                   x.errors ? strprintf(" [%d failed]", x.errors).c_str() : "");
  }
  const int nf = fair.cases - fair.errors;
  s += strprintf("%-15s %s %s %s %s %s %s %s\n", "all hidden", pct(fair.first, nf).c_str(),
                 pct(fair.top2, nf).c_str(), pct(fair.gains, nf).c_str(),
                 pct(fair.supported, nf).c_str(), pct(fair.reachable, fair.measured).c_str(),
                 pct(fair.reached, fair.reachable).c_str(),
                 pct(fair.search_short, fair.missed_searched).c_str());
  for (const auto& [c, x] : t)
    if (x.climbed > 0)
      s += strprintf(
          "%s, climbed from the start model (diagnose --auto): every hidden effect "
          "added %s, at least one %s\n",
          c.c_str(), pct(x.climb_all, x.climbed).c_str(), pct(x.climb_some, x.climbed).c_str());
  if (t.count("none")) {
    const Tally& x = t.at("none");
    s += strprintf("controls: %d, supported false findings %s", x.cases - x.errors,
                   pct(x.alarms, x.cases - x.errors).c_str());
    std::map<std::string, int> what;
    for (const auto& o : outcomes)
      if (o.false_alarm) ++what[o.false_effect];
    std::string w;
    for (const auto& [e, n] : what) w += strprintf("%s%s %d", w.empty() ? "" : ", ", e.c_str(), n);
    s += (w.empty() ? "" : " (" + w + ")") + "\n";
  }
  // Confusion: hidden effect (rows, single-effect cases) against the first finding (columns).
  std::vector<std::string> cols;
  for (const auto& c : random_loop_categories())
    if (c != "none" && c != "pair") cols.push_back(c);
  s += "\nconfusion (rows: hidden; columns: named first; '.' none supported first)\n";
  s += strprintf("%-15s", "");
  for (const auto& c : cols) s += strprintf(" %4.4s", c.c_str());
  s += strprintf(" %4s\n", "none");
  for (const auto& r : cols) {
    std::map<std::string, int> row;
    int none = 0;
    for (const auto& o : outcomes)
      if (o.loop.hidden.size() == 1 && o.loop.hidden.front() == r && o.error.empty()) {
        if (o.first.empty())
          ++none;
        else
          ++row[o.first];
      }
    s += strprintf("%-15s", r.c_str());
    for (const auto& c : cols) s += row[c] ? strprintf(" %4d", row[c]) : std::string("    .");
    s += strprintf(" %4d\n", none);
  }
  s += strprintf("time: %.0f s in %d cases (%.1f s each)\n", all.seconds, all.cases,
                 all.cases ? all.seconds / all.cases : 0.0);
  return s;
}

std::string format_benchmark_pair(const std::vector<BenchmarkOutcome>& dev,
                                  const std::vector<BenchmarkOutcome>& test) {
  Tally da, df, ta, tf;
  const auto d = tally(dev, da, df);
  const auto t = tally(test, ta, tf);
  std::string s = strprintf("%-15s | %-38s | %-38s\n", "", "development seeds", "test seeds");
  s += strprintf("%-15s | %-12s %-12s %-12s | %-12s %-12s %-12s\n", "hidden", "first", "top two",
                 "gain >= 2", "first", "top two", "gain >= 2");
  auto row = [&](const std::string& name, const Tally* a, const Tally* b) {
    auto cells = [](const Tally* x) {
      if (!x) return strprintf("%-12s %-12s %-12s", "-", "-", "-");
      const int n = x->cases - x->errors;
      return pct(x->first, n) + " " + pct(x->top2, n) + " " + pct(x->gains, n);
    };
    return strprintf("%-15s | %s | %s\n", name.c_str(), cells(a).c_str(), cells(b).c_str());
  };
  for (const auto& c : random_loop_categories()) {
    if (c == "none") continue;
    s += row(c, d.count(c) ? &d.at(c) : nullptr, t.count(c) ? &t.at(c) : nullptr);
  }
  s += row("all hidden", &df, &tf);
  auto alarms = [](const std::map<std::string, Tally>& m) {
    if (!m.count("none")) return std::string("-");
    const Tally& x = m.at("none");
    return pct(x.alarms, x.cases - x.errors);
  };
  s += strprintf("%-15s | %-38s | %-38s\n", "false findings", alarms(d).c_str(), alarms(t).c_str());
  auto climbs = [](const std::map<std::string, Tally>& m) {
    int n = 0, all = 0;
    for (const auto& [c, x] : m) {
      n += x.climbed;
      all += x.climb_all;
    }
    return n > 0 ? pct(all, n) : std::string("-");
  };
  if (const std::string cd = climbs(d), ct = climbs(t); cd != "-" || ct != "-")
    s += strprintf("%-15s | %-38s | %-38s\n", "pair, --auto", cd.c_str(), ct.c_str());
  return s;
}

}  // namespace valvediag
