#include "valvediag/effect_judge.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

#include "valvediag/autocorrelation.hpp"

namespace valvediag {

namespace {

// The residual of the simulated output and its AR noise model, fitted to the estimation part by
// least squares, its order chosen by BIC (Box-Jenkins: y = G x + e / A_n).
struct NoiseModel {
  std::vector<double> r, phi;
  bool ok = false;
};
NoiseModel noise_model(const ModelFit& fit, const std::vector<double>& y) {
  NoiseModel m;
  const std::size_t N = y.size();
  if (fit.status == ModelFitStatus::NoStableModel || fit.y_sim.size() != N) return m;
  const std::size_t t0 = fit.first_sample;
  const std::size_t e0 = std::min(fit.estimation_end ? fit.estimation_end : N, N);
  m.r.assign(N, 0.0);
  for (std::size_t t = 0; t < N; ++t) m.r[t] = y[t] - fit.y_sim[t];
  for (double v : m.r)
    if (!std::isfinite(v)) return m;
  constexpr int kMax = 10;
  if (e0 < t0 + 4 * kMax) return m;
  const auto& r = m.r;
  double best_bic = std::numeric_limits<double>::infinity();
  const std::size_t from = t0 + kMax;
  const double n = static_cast<double>(e0 - from);
  for (int p = 0; p <= kMax; ++p) {
    Eigen::MatrixXd G = Eigen::MatrixXd::Zero(p, p);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(p);
    double rr = 0.0;
    for (std::size_t t = from; t < e0; ++t) {
      rr += r[t] * r[t];
      for (int i = 0; i < p; ++i) {
        g(i) += r[t] * r[t - 1 - i];
        for (int j = 0; j < p; ++j) G(i, j) += r[t - 1 - i] * r[t - 1 - j];
      }
    }
    const Eigen::VectorXd phi = p > 0 ? Eigen::VectorXd(G.ldlt().solve(g)) : Eigen::VectorXd();
    const double sse = p > 0 ? rr - phi.dot(g) : rr;
    if (!(sse > 0) || !std::isfinite(sse)) continue;
    const double bic = n * std::log(sse / n) + p * std::log(n);
    if (bic < best_bic) {
      best_bic = bic;
      m.phi.assign(phi.data(), phi.data() + p);
      m.ok = true;
    }
  }
  return m;
}

// The simulated output plus the residual the noise model predicts k samples ahead.
std::vector<double> predict_with(const ModelFit& fit, const NoiseModel& m, std::size_t k) {
  const std::size_t N = m.r.size();
  std::vector<double> out(fit.y_sim.size(), Judgement::kNaN);
  if (!m.ok) return out;
  const std::size_t p = m.phi.size();
  std::vector<double> w(k);
  for (std::size_t t = fit.first_sample + p + k; t < N; ++t) {
    const std::size_t origin = t - k;
    for (std::size_t s = origin + 1; s <= t; ++s) {
      double v = 0.0;
      for (std::size_t i = 1; i <= p; ++i) {
        const std::size_t j = s - i;
        v += m.phi[i - 1] * (j <= origin ? m.r[j] : w[j - origin - 1]);
      }
      w[s - origin - 1] = v;
    }
    out[t] = fit.y_sim[t] + w[k - 1];
  }
  return out;
}

}  // namespace

Prediction predict(const ModelFit& fit, const std::vector<double>& y, std::size_t horizon) {
  Prediction p;
  p.horizon = horizon;
  const NoiseModel m = noise_model(fit, y);
  p.noise_order = static_cast<int>(m.phi.size());
  p.y_k = predict_with(fit, m, horizon);
  p.valid = std::any_of(p.y_k.begin(), p.y_k.end(), [](double v) { return std::isfinite(v); });
  return p;
}

double prediction_fit_percent(const std::vector<double>& y, const Prediction& p, std::size_t from,
                              std::size_t to) {
  to = std::min(to, std::min(y.size(), p.y_k.size()));
  double mean = 0.0;
  std::size_t n = 0;
  for (std::size_t t = from; t < to; ++t)
    if (std::isfinite(p.y_k[t])) {
      mean += y[t];
      ++n;
    }
  if (n < 2) return Judgement::kNaN;
  mean /= static_cast<double>(n);
  double num = 0.0, den = 0.0;
  for (std::size_t t = from; t < to; ++t)
    if (std::isfinite(p.y_k[t])) {
      num += (y[t] - p.y_k[t]) * (y[t] - p.y_k[t]);
      den += (y[t] - mean) * (y[t] - mean);
    }
  if (!(den > 0) || !std::isfinite(num)) return Judgement::kNaN;
  return 100.0 * (1.0 - std::sqrt(num / den));
}

double diebold_mariano(const std::vector<double>& ea, const std::vector<double>& eb,
                       double* n_eff) {
  const std::size_t n = std::min(ea.size(), eb.size());
  if (n_eff) *n_eff = 0.0;
  if (n < 10) return Judgement::kNaN;
  std::vector<double> d(n);
  double mean = 0.0;
  for (std::size_t t = 0; t < n; ++t) {
    d[t] = ea[t] * ea[t] - eb[t] * eb[t];
    mean += d[t];
  }
  mean /= static_cast<double>(n);
  double var = 0.0;
  for (double v : d) var += (v - mean) * (v - mean);
  var /= static_cast<double>(n - 1);
  if (!(var > 0) || !std::isfinite(var)) return Judgement::kNaN;
  const double m = effective_sample_size(d);
  if (n_eff) *n_eff = m;
  return mean / std::sqrt(var / m);
}

double confidence(const Judgement& j) {
  if (!(j.estimation_lr > j.estimation_penalty) || !(j.validation_lr > 0)) return 0.0;
  return std::erf(std::sqrt(j.validation_lr / 2.0));
}

double likelihood_ratio(const std::vector<double>& ea, const std::vector<double>& eb) {
  const std::size_t n = std::min(ea.size(), eb.size());
  if (n < 10) return Judgement::kNaN;
  double sa = 0.0, sb = 0.0;
  for (std::size_t t = 0; t < n; ++t) {
    sa += ea[t] * ea[t];
    sb += eb[t] * eb[t];
  }
  if (!(sa > 0 && sb > 0)) return Judgement::kNaN;
  return effective_sample_size(sb < sa ? eb : ea) * std::log(sa / sb);
}

namespace {

// The errors of both predictions over [from, to) where both predict.
void paired_errors(const std::vector<double>& y, const Prediction& a, const Prediction& b,
                   std::size_t from, std::size_t to, std::vector<double>& ea,
                   std::vector<double>& eb) {
  ea.clear();
  eb.clear();
  to = std::min({to, y.size(), a.y_k.size(), b.y_k.size()});
  for (std::size_t t = from; t < to; ++t)
    if (std::isfinite(a.y_k[t]) && std::isfinite(b.y_k[t])) {
      ea.push_back(y[t] - a.y_k[t]);
      eb.push_back(y[t] - b.y_k[t]);
    }
}

double fit_of(const std::vector<double>& y, const Prediction& a, const Prediction& b,
              const Prediction& which, std::size_t from, std::size_t to) {
  // Scored over the samples both predict, so that the two fits compare the same samples.
  Prediction common = which;
  to = std::min({to, y.size(), a.y_k.size(), b.y_k.size()});
  for (std::size_t t = 0; t < common.y_k.size(); ++t)
    if (t < from || t >= to || !std::isfinite(a.y_k[t]) || !std::isfinite(b.y_k[t]))
      common.y_k[t] = Judgement::kNaN;
  return prediction_fit_percent(y, common, from, to);
}

double sum_squares(const std::vector<double>& e) {
  double s = 0.0;
  for (double v : e) s += v * v;
  return s;
}

}  // namespace

Judgement judge(const std::vector<double>& y, std::size_t e0, const Prediction& model,
                const Prediction& trial, double added_parameters, const JudgeOptions& opt) {
  Judgement j;
  j.horizon = trial.horizon;
  added_parameters += trial.noise_order - model.noise_order;
  j.added_parameters = added_parameters;
  const std::size_t N = y.size();
  if (!trial.valid) return j;
  if (!model.valid) {
    // Nothing to compare with (the model has no stable linear part): the trial against PV held
    // at its value k samples back, the naive prediction at the same horizon.
    Prediction naive;
    naive.horizon = trial.horizon;
    naive.valid = true;
    naive.y_k.assign(N, Judgement::kNaN);
    for (std::size_t t = trial.horizon; t < N; ++t) naive.y_k[t] = y[t - trial.horizon];
    return judge(y, e0, naive, trial, added_parameters, opt);
  }
  j.model_estimation_fit = fit_of(y, model, trial, model, 0, e0);
  j.trial_estimation_fit = fit_of(y, model, trial, trial, 0, e0);
  j.model_validation_fit = fit_of(y, model, trial, model, e0, N);
  j.trial_validation_fit = fit_of(y, model, trial, trial, e0, N);
  j.estimation_gain = j.trial_estimation_fit - j.model_estimation_fit;
  j.validation_gain = j.trial_validation_fit - j.model_validation_fit;

  // Both parts' likelihood ratios count the model's independent errors (N_eff of the model's
  // k-step errors, the same for every trial of one model): the ratios of several trials then
  // rank as their errors do, and two trials differ by the difference of their ratios.
  std::vector<double> ea, eb;
  paired_errors(y, model, trial, e0, N, ea, eb);
  j.validation_t = diebold_mariano(ea, eb);
  if (eb.size() >= 10 && sum_squares(ea) > 0 && sum_squares(eb) > 0) {
    j.validation_n_eff = effective_sample_size(ea);
    j.validation_lr = j.validation_n_eff * std::log(sum_squares(ea) / sum_squares(eb));
  }
  paired_errors(y, model, trial, 0, e0, ea, eb);
  const double s0 = sum_squares(ea), s1 = sum_squares(eb);
  if (eb.size() >= 10 && s0 > 0 && s1 > 0) {
    j.estimation_n_eff = effective_sample_size(ea);
    j.estimation_lr = j.estimation_n_eff * std::log(s0 / s1);
    j.estimation_penalty = added_parameters * std::log(std::max(j.estimation_n_eff, 2.0));
  }
  j.significant = j.validation_lr >= opt.critical_lr && j.estimation_lr > j.estimation_penalty;
  return j;
}

}  // namespace valvediag
