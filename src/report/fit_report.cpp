#include "valvediag/report/fit_report.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "number_format.hpp"
#include "valvediag/report/json_number.hpp"

namespace valvediag {

const char* method_name(FitMethod m) {
  return m == FitMethod::Joint ? "joint" : "alternation";
}

FitSeries fit_series(const IdentificationResult& r, const std::vector<double>& u,
                     const std::vector<double>& y) {
  FitSeries s;
  s.x_hat = simulate_valve(r.model, u);
  s.y_sim = simulate_arx(r.model, s.x_hat, y, r.first_sample);
  s.residual.resize(y.size());
  for (std::size_t t = 0; t < y.size(); ++t) s.residual[t] = y[t] - s.y_sim[t];
  return s;
}

ResidualAnalysis analyse_fit(const IdentificationResult& r, const std::vector<double>& u,
                             const std::vector<double>& y, const FitSeries& s) {
  ResidualAnalysisOptions o;
  o.model_delay = r.model.block == LinearBlock::Identity
                      ? 0
                      : static_cast<std::size_t>(r.model.structure.nk + 1);
  return analyse_residual(u, y, s.y_sim, r.first_sample, r.estimation_end, o);
}

namespace {

std::string fit_num(double v, int prec = 4) {
  return report_format::fixed(v, prec);
}

std::string polynomial(const std::vector<double>& coef, int first_power, bool leading_one) {
  std::ostringstream s;
  if (leading_one) s << "1";
  for (std::size_t i = 0; i < coef.size(); ++i) {
    const double c = coef[i];
    const bool first = !leading_one && i == 0;
    if (first)
      s << fit_num(c);
    else
      s << (c < 0 ? " - " : " + ") << fit_num(std::abs(c));
    s << " q^-" << first_power + static_cast<int>(i);
  }
  return s.str();
}

double time_of(const FitContext& ctx, std::size_t k) {
  return ctx.time && k < ctx.time->size() ? (*ctx.time)[k]
                                          : static_cast<double>(k) * ctx.sample_period;
}

// The regions worth naming: well above their share of the samples, and a real part of the error.
std::vector<const ResidualRegion*> notable_regions(const ResidualAnalysis& a) {
  std::vector<const ResidualRegion*> v;
  for (const auto& g : a.regions)
    if (g.excess >= 1.5 && g.share >= 0.1) v.push_back(&g);
  std::sort(v.begin(), v.end(), [](auto* x, auto* y) { return x->excess > y->excess; });
  if (v.size() > 4) v.resize(4);
  return v;
}

std::string format_where(const ResidualAnalysis& a, const FitContext& ctx) {
  std::ostringstream o;
  o << "where it fails: residual RMS " << fit_num(a.rms, 3) << ", white-noise level "
    << fit_num(a.noise_level, 3) << "\n";
  std::size_t shown = 0;
  for (const auto& iv : a.intervals) {
    if (shown++ == 3) break;
    o << "           t " << fit_num(time_of(ctx, iv.begin), 1) << " .. "
      << fit_num(time_of(ctx, iv.end - 1), 1) << " s: " << fit_num(100 * iv.share, 0)
      << " % of the squared error (RMS " << fit_num(iv.rms, 3) << ")\n";
  }
  for (const auto* g : notable_regions(a))
    o << "           " << g->label << ": " << fit_num(100 * g->share, 0) << " % of the error in "
      << fit_num(100 * g->share / g->excess, 0) << " % of the samples (mean residual "
      << fit_num(g->mean, 3) << ")\n";
  for (const auto& t : a.tests)
    if (t.score >= 0.3) {
      o << "           " << t.name << " " << fit_num(t.score, 2);
      for (std::size_t i = 0; i < t.effects.size(); ++i) o << (i ? ", " : " -> ") << t.effects[i];
      o << ": " << t.detail << "\n";
    }
  return o.str();
}

nlohmann::json where_json(const ResidualAnalysis& a, const FitContext& ctx) {
  using nlohmann::json;
  json w;
  w["residual_rms"] = a.rms;
  w["noise_level"] = a.noise_level;
  w["op_reversals"] = a.reversals;
  json iv = json::array();
  for (const auto& i : a.intervals)
    iv.push_back({{"begin_sample", i.begin},
                  {"end_sample", i.end},
                  {"t_begin_s", time_of(ctx, i.begin)},
                  {"t_end_s", time_of(ctx, i.end - 1)},
                  {"rms", i.rms},
                  {"share", i.share}});
  w["intervals"] = iv;
  json rg = json::array();
  for (const auto& g : a.regions)
    rg.push_back({{"kind", g.kind},
                  {"label", g.label},
                  {"lo", g.lo},
                  {"hi", g.hi},
                  {"samples", g.samples},
                  {"rms", g.rms},
                  {"mean", g.mean},
                  {"share", g.share},
                  {"excess", g.excess}});
  w["regions"] = rg;
  json ts = json::array();
  for (const auto& t : a.tests)
    ts.push_back({{"name", t.name},
                  {"effects", t.effects},
                  {"statistic", t.statistic},
                  {"score", t.score},
                  {"detail", t.detail}});
  w["tests"] = ts;
  return w;
}

std::string format_stiction(const StictionQuantification& q) {
  std::ostringstream o;
  o << "stiction:  ";
  if (!q.valid) return o.str() + q.summary + "\n";
  if (q.stiction) {
    o << "fs " << fit_num(q.overall.fs_percent, 2) << " %, fd " << fit_num(q.overall.fd_percent, 2)
      << " % of travel (He; band " << fit_num(q.overall.band_percent, 2) << " %, slip jump "
      << fit_num(q.overall.jump_percent, 2) << " %), resolution "
      << fit_num(q.resolution_percent, 2) << " %\n";
    if (!q.jump_identified && !q.refined)
      o << "           the data's sweeps are shorter than 2 fs: the split of the band into fs and "
           "fd is not identified\n";
  } else if (q.refined) {
    o << "none resolved ("
      << (q.interval.valid && q.interval.fs_lo > 0
              ? "He's band " + fit_num(q.overall.band_percent, 2) + " % is below the grid step " +
                    fit_num(q.resolution_percent, 2) + " %"
              : std::string("a valve without stiction fits the data as well"))
      << "; best fs " << fit_num(q.overall.fs_percent, 2) << " %, fd "
      << fit_num(q.overall.fd_percent, 2) << " %)\n";
  } else {
    o << "none resolved (band below the grid step " << fit_num(q.resolution_percent, 2) << " %)\n";
  }
  const StictionInterval& iv = q.interval;
  if (iv.valid)
    o << "           the data fit fs "
      << (iv.fs_open_above ? fit_num(iv.fs_lo, 2) + " % or more (up to the OP span " +
                                 fit_num(iv.fs_hi, 2) + " %: the data do not bound it)"
                           : fit_num(iv.fs_lo, 2) + "-" + fit_num(iv.fs_hi, 2) + " %")
      << ", fd " << fit_num(iv.fd_lo, 2) << "-" << fit_num(iv.fd_hi, 2) << " % within "
      << fit_num(100 * iv.level(), 0) << " % (profile likelihood, "
      << fit_num(iv.effective_samples, 0) << " effective samples, lattice step "
      << fit_num(iv.step_percent, 2) << " %" << (iv.capped ? "; at least that wide" : "") << ")\n";
  if (!q.data_given) o << "           (probed over the whole grid: the OP data was not given)\n";
  for (const auto& g : q.regions) {
    o << "           OP " << fit_num(g.op_lo, 1) << "-" << fit_num(g.op_hi, 1) << ": ";
    if (!g.visited)
      o << "not visited by the data (" << g.data_reversals << " reversals)";
    else if (!g.valid || !std::isfinite(g.figures.fs_percent))
      o << "not measured";
    else if (!g.stiction)
      o << "no stiction resolved";
    else
      o << "fs " << fit_num(g.figures.fs_percent, 2) << " %, fd "
        << fit_num(g.figures.fd_percent, 2) << " %"
        << (std::isfinite(g.fs_lo) ? " (the data fit fs " + fit_num(g.fs_lo, 2) + "-" +
                                         fit_num(g.fs_hi, 2) + " % as well)"
                                   : std::string());
    o << "\n";
  }
  return o.str();
}

nlohmann::json interval_json(const StictionInterval& iv) {
  if (!iv.valid) return nullptr;
  return {{"fs_lo_percent", iv.fs_lo},
          {"fs_hi_percent", iv.fs_hi},
          {"fd_lo_percent", iv.fd_lo},
          {"fd_hi_percent", iv.fd_hi},
          {"level", iv.level()},
          {"effective_samples", iv.effective_samples},
          {"cost_ratio", iv.cost_ratio},
          {"step_percent", iv.step_percent},
          {"points", iv.points},
          {"capped", iv.capped},
          {"fs_open_above", iv.fs_open_above}};
}

nlohmann::json stiction_json(const StictionQuantification& q) {
  using nlohmann::json;
  json rg = json::array();
  for (const auto& g : q.regions)
    rg.push_back({{"op_lo", g.op_lo},
                  {"op_hi", g.op_hi},
                  {"fs_percent", json_number(g.figures.fs_percent)},
                  {"fd_percent", json_number(g.figures.fd_percent)},
                  {"fs_lo_percent", json_number(g.fs_lo)},
                  {"fs_hi_percent", json_number(g.fs_hi)},
                  {"band_percent", json_number(g.figures.band_percent)},
                  {"jump_percent", json_number(g.figures.jump_percent)},
                  {"visited", g.visited},
                  {"valid", g.valid},
                  {"stiction", g.stiction},
                  {"data_reversals", g.data_reversals},
                  {"samples", g.samples}});
  return {{"fs_percent", json_number(q.overall.fs_percent)},
          {"fd_percent", json_number(q.overall.fd_percent)},
          {"band_percent", json_number(q.overall.band_percent)},
          {"jump_percent", json_number(q.overall.jump_percent)},
          {"he_fit_percent", json_number(q.overall.fit_percent)},
          {"stiction", q.stiction},
          {"valid", q.valid},
          {"jump_identified", q.jump_identified},
          {"resolution_percent", q.resolution_percent},
          {"interval", interval_json(q.interval)},
          {"op_lo", q.op_lo},
          {"op_hi", q.op_hi},
          {"probe", q.data_given ? "data" : "grid"},
          {"summary", q.summary},
          {"regions", rg}};
}

}  // namespace

StictionQuantification fit_stiction(const IdentificationResult& r, const FitContext& ctx) {
  if (ctx.stiction) return *ctx.stiction;
  StictionQuantificationOptions opt;
  opt.threads = ctx.threads;
  if (!ctx.op) return quantify_stiction(r.model, {}, opt);
  const std::size_t end = std::min(ctx.op->size(), r.estimation_end);
  const auto cut = [end](const std::vector<double>& v) {
    return std::vector<double>(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(end));
  };
  if (ctx.pv && ctx.pv->size() == ctx.op->size())
    return quantify_stiction(r.model, cut(*ctx.op), cut(*ctx.pv), opt);
  return quantify_stiction(r.model, cut(*ctx.op), opt);
}

std::string format_summary(const IdentificationResult& r, const FitContext& ctx) {
  std::ostringstream o;
  const auto& m = r.model;
  const auto& s = r.best.structure;
  o << "data:      " << ctx.data_name << " (" << ctx.samples << " samples, Ts "
    << fit_num(ctx.sample_period, 3) << " s, OP " << fit_num(m.grid.umin, 2) << " .. "
    << fit_num(m.grid.umax, 2) << ")\n";
  if (r.status == IdentificationStatus::NoStableModel) {
    o << "result:    no stable model in the grid: every fitted linear block had a pole on or "
         "outside the\n"
         "           unit circle (drift in the data?). Try --nk-max/--na-max, detrend, or --output "
         "mv.\n";
    return o.str();
  }
  if (m.block == LinearBlock::Identity) {
    o << "model:     Preisach valve (L = " << s.L
      << ") fitted to the measured valve position (identity block)\n";
  } else {
    o << "model:     Preisach valve (L = " << s.L << ") -> ARX (na = " << s.na << ", nb = " << s.nb
      << ", nk = " << s.nk << ")   [" << ctx.method << " method]\n";
    o << "           A(q) = " << polynomial(m.a, 1, true) << "\n";
    o << "           B(q) = " << polynomial(m.b, s.nk + 1, false)
      << "   (||b|| = 1, gain sign in b)\n";
  }
  o << "           c = " << fit_num(m.c) << "\n";
  o << "fitness:   " << fit_num(r.fitness_percent, 2)
    << " % on estimation data (simulated output: the model driven by OP alone)";
  if (std::isfinite(r.validation_fitness_percent))
    o << ", " << fit_num(r.validation_fitness_percent, 2) << " % on validation data";
  o << "\n";
  int nz = 0;
  for (double w : m.mu) nz += w > 0;
  o << "valve:     " << nz << " nonzero weights of " << m.grid.relay_count() << " relays (kappa "
    << fit_num(r.best.kappa, 2) << ", BIC " << fit_num(r.best.bic, 1) << ")\n";
  o << format_stiction(fit_stiction(r, ctx));
  o << "memory:    initial relay state ";
  if (m.initial_history.size() <= 1) {
    o << "as if OP came up from its minimum\n";
  } else {
    o << "estimated: OP was at level " << m.initial_history[0] << " then " << m.initial_history[1]
      << " of " << m.grid.L << " before the record (+" << fit_num(r.initial_memory_gain_percent, 2)
      << " fitness points)\n";
  }
  o << "identifiability: " << r.identifiability.summary << "\n";
  if (ctx.residual) o << format_where(*ctx.residual, ctx);
  int unstable = 0;
  for (const auto& c : r.configurations) unstable += !c.stable;
  o << "solver:    " << to_string(r.best.status) << " (" << r.best.stop_reason << "); "
    << r.configurations.size() << " configurations (" << unstable << " rejected as unstable), "
    << r.total_iterations << " solver iterations, " << fit_num(r.elapsed_s, 3) << " s\n";
  return o.str();
}

nlohmann::json to_json(const IdentificationResult& r, const FitContext& ctx) {
  using nlohmann::json;
  const auto& m = r.model;
  const auto& s = r.best.structure;
  json j;
  j["data"] = {{"source", ctx.data_name},
               {"samples", ctx.samples},
               {"sample_period_s", ctx.sample_period},
               {"output", ctx.output_name},
               {"estimation_samples", r.estimation_end},
               {"first_simulated_sample", r.first_sample}};
  j["status"] = r.status == IdentificationStatus::Ok ? "ok" : "no-stable-model";
  j["model"] = m.block == LinearBlock::Identity ? "preisach (identity linear block)"
                                                : "preisach-hammerstein";
  j["method"] = ctx.method;
  j["structure"] = {{"na", s.na}, {"nb", s.nb}, {"nk", s.nk}, {"L", s.L}};
  j["fitness_percent"] = json_number(r.fitness_percent);
  if (r.estimation_end < ctx.samples)
    j["validation_fitness_percent"] = json_number(r.validation_fitness_percent);
  j["a"] = m.a;
  j["b"] = m.b;
  j["c"] = m.c;
  json mu = json::array();
  const auto& g = m.grid;
  for (int i = 1; i <= g.L; ++i)
    for (int jj = i; jj <= g.L; ++jj) {
      const double w = m.mu.empty() ? 0.0 : m.mu[static_cast<std::size_t>(g.relay_index(i, jj))];
      if (w <= 0) continue;
      // Relay (i, j) switches down below (u_i + u_{i+1})/2 and up above (u_j + u_{j+1})/2.
      mu.push_back({{"i", i},
                    {"j", jj},
                    {"weight", w},
                    {"down_threshold", g.threshold(i) + g.delta() / 2},
                    {"up_threshold", g.threshold(jj) + g.delta() / 2}});
    }
  j["mu"] = mu;
  if (r.status == IdentificationStatus::Ok) j["stiction"] = stiction_json(fit_stiction(r, ctx));
  j["preisach"] = {{"umin", g.umin},
                   {"umax", g.umax},
                   {"L", g.L},
                   {"relays", g.relay_count()},
                   {"initial_history_levels", m.initial_history},
                   {"initial_memory_gain_percent", r.initial_memory_gain_percent}};
  const auto& id = r.identifiability;
  j["identifiability"] = {{"kind", to_string(id.kind)},
                          {"relays", id.relays},
                          {"switching_relays", id.switching_relays},
                          {"distinct_histories", id.distinct_histories},
                          {"identifiable_combinations", id.identifiable_combinations},
                          {"reversals", id.reversals},
                          {"threshold_coverage", id.threshold_coverage},
                          {"summary", id.summary}};
  int unstable = 0;
  for (const auto& c : r.configurations) unstable += !c.stable;
  j["rejected_unstable"] = unstable;
  j["solver"] = {{"status", to_string(r.best.status)},
                 {"stop_reason", r.best.stop_reason},
                 {"kappa", r.best.kappa},
                 {"bic", json_number(r.best.bic)},
                 {"stable", r.best.stable},
                 {"configurations", r.configurations.size()}};
  if (ctx.residual) j["where"] = where_json(*ctx.residual, ctx);
  j["iterations"] = r.total_iterations;
  j["elapsed_s"] = r.elapsed_s;
  return j;
}

}  // namespace valvediag
