#include "valvediag/fit_report.hpp"

#include <cmath>
#include <cstdio>
#include <sstream>

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

namespace {

std::string num(double v, int prec = 4) {
  if (!std::isfinite(v)) return "n/a";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", prec, v);
  return buf;
}

std::string polynomial(const std::vector<double>& coef, int first_power, bool leading_one) {
  std::ostringstream s;
  if (leading_one) s << "1";
  for (std::size_t i = 0; i < coef.size(); ++i) {
    const double c = coef[i];
    const bool first = !leading_one && i == 0;
    if (first)
      s << num(c);
    else
      s << (c < 0 ? " - " : " + ") << num(std::abs(c));
    s << " q^-" << first_power + static_cast<int>(i);
  }
  return s.str();
}

nlohmann::json number_or_null(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
}

}  // namespace

std::string format_summary(const IdentificationResult& r, const FitContext& ctx) {
  std::ostringstream o;
  const auto& m = r.model;
  const auto& s = r.best.structure;
  o << "data:      " << ctx.data_name << " (" << ctx.samples << " samples, Ts "
    << num(ctx.sample_period, 3) << " s, OP " << num(m.grid.umin, 2) << " .. "
    << num(m.grid.umax, 2) << ")\n";
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
  o << "           c = " << num(m.c) << "\n";
  o << "fitness:   " << num(r.fitness_percent, 2)
    << " % on estimation data (simulated output, eq 20)";
  if (std::isfinite(r.validation_fitness_percent))
    o << ", " << num(r.validation_fitness_percent, 2) << " % on validation data";
  o << "\n";
  int nz = 0;
  for (double w : m.mu) nz += w > 0;
  o << "valve:     " << nz << " nonzero weights of " << m.grid.relay_count() << " relays (kappa "
    << num(r.best.kappa, 2) << ", BIC " << num(r.best.bic, 1) << ")\n";
  o << "memory:    initial relay state ";
  if (m.initial_history.size() <= 1) {
    o << "as if OP came up from its minimum\n";
  } else {
    o << "estimated: OP was at level " << m.initial_history[0] << " then " << m.initial_history[1]
      << " of " << m.grid.L << " before the record (+" << num(r.initial_memory_gain_percent, 2)
      << " fitness points)\n";
  }
  o << "identifiability: " << to_string(r.identifiability.kind) << ": " << r.identifiability.summary
    << "\n";
  int unstable = 0;
  for (const auto& c : r.configurations) unstable += !c.stable;
  o << "solver:    " << to_string(r.best.status) << " (" << r.best.stop_reason << "); "
    << r.configurations.size() << " configurations (" << unstable << " rejected as unstable), "
    << r.total_iterations << " solver iterations, " << num(r.elapsed_s, 3) << " s\n";
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
  j["fitness_percent"] = number_or_null(r.fitness_percent);
  if (r.estimation_end < ctx.samples)
    j["validation_fitness_percent"] = number_or_null(r.validation_fitness_percent);
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
                 {"bic", number_or_null(r.best.bic)},
                 {"stable", r.best.stable},
                 {"configurations", r.configurations.size()}};
  j["iterations"] = r.total_iterations;
  j["elapsed_s"] = r.elapsed_s;
  return j;
}

}  // namespace valvediag
