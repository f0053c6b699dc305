// He's model fitted to the identified Preisach valve's response to the probe (stiction_probe.hpp):
// the Preisach figures, overall and per OP region (quantify_stiction without pv).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <stdexcept>
#include <vector>

#include "stiction_probe.hpp"
#include "stiction_result.hpp"
#include "valvediag/core/stiction_quantification.hpp"

namespace valvediag {

using detail::data_probe;
using detail::figures;
using detail::forc_probe;
using detail::Probe;
using detail::stiction_sentence;
using detail::unmeasured;

namespace {

// He's model, the flowchart of HeStiction in src/sim (the core does not depend on the
// simulator), evaluated for an input that moves linearly between samples: every slip the
// flowchart would make at a fine enough sampling is made, at the exact input where |u_cum|
// passes fs. Sampled as in the flowchart, a ramp of r per sample slips r / 2 late on average, so
// the staircase steps would be fs - fd plus that, and the fit would report a jump too small by
// it: the probe's sampling is ours, not the valve's.
struct He {
  double fs, fd;
  double u_prev = 0.0, x = 0.0, u_r = 0.0;
  // At u0, having last slipped up at u0 - phase (0 <= phase < fs - fd): the phase of He's
  // staircase. It is set by the valve's history, which the probe does not know: it is fitted.
  void reset(double u0, double phase) {
    u_prev = u0;
    u_r = fd + phase;
    x = u0 - u_r;
  }
  double step(double u) {
    const double du = u - u_prev;
    u_prev = u;
    const double d = du > 0 ? 1.0 : -1.0;
    const double pushed = d * u_r + std::abs(du);  // force along the move
    if (!(pushed > fs)) {
      u_r += du;  // stick
      return x;
    }
    // First slip after fs - d u_r of travel, then one every fs - fd while the input moves on.
    const double after = pushed - fs;
    const double jump = fs - fd;
    const double rest = jump > 0 ? after - jump * std::floor(after / jump) : 0.0;
    u_r = d * (fd + rest);
    x = u - u_r;
    return x;
  }
};

// Sums for a least-squares fit of x ~ s He + c over one set of samples.
struct Sums {
  double n = 0, sp = 0, spp = 0, sh = 0, shh = 0, sph = 0;
  void add(double P, double H) {
    n += 1;
    sp += P;
    spp += P * P;
    sh += H;
    shh += H * H;
    sph += P * H;
  }
  // A run of samples at one H: r holds their n, sums of P and of P^2.
  void add_run(const Sums& r, double H) {
    n += r.n;
    sp += r.sp;
    spp += r.spp;
    sh += r.n * H;
    shh += r.n * H * H;
    sph += r.sp * H;
  }
  double var_p() const { return n > 0 ? spp - sp * sp / n : 0.0; }
  // Residual sum of squares with s and c free (s > 0), and that s.
  double cost_free(double* s_out) const {
    if (n < 2) {
      *s_out = 0.0;
      return 0.0;
    }
    const double vh = shh - sh * sh / n, cph = sph - sp * sh / n;
    if (!(vh > 1e-12 * (1.0 + shh)) || cph <= 0) {
      *s_out = 0.0;
      return var_p();
    }
    *s_out = cph / vh;
    return std::max(0.0, var_p() - cph * cph / vh);
  }
  // With s fixed, c free.
  double cost_fixed(double s) const {
    if (n < 2) return 0.0;
    const double vh = shh - sh * sh / n, cph = sph - sp * sh / n;
    return std::max(0.0, var_p() - 2 * s * cph + s * s * vh);
  }
};

// The probe's samples merged into runs of one grid level (and one set they count in): He's
// valve does not move while its input stays put, so a run's samples enter the sums together,
// and a pass costs the level changes, not the samples.
struct Runs {
  std::vector<double> uq;
  std::vector<char> scored;
  std::vector<int> region;
  std::vector<Sums> x;  // the run's Preisach positions less their mean (H left 0)
  // Subtracted from He's position: the sums are of deviations, not of ~50 % levels, so that
  // costs that differ far below the variance are not lost to cancellation.
  double centre = 0.0;
};

Runs runs_of(const Probe& p, const std::vector<int>& region_of_sample, bool merge) {
  Runs r;
  double x_mean = 0.0;
  for (std::size_t t = 0; t < p.u.size(); ++t) {
    x_mean += p.x[t] / static_cast<double>(p.u.size());
    r.centre += p.uq[t] / static_cast<double>(p.u.size());
  }
  for (std::size_t t = 0; t < p.u.size(); ++t) {
    const int reg = region_of_sample.empty() ? -1 : region_of_sample[t];
    if (r.uq.empty() || !merge || p.uq[t] != r.uq.back() || p.scored[t] != r.scored.back() ||
        reg != r.region.back()) {
      r.uq.push_back(p.uq[t]);
      r.scored.push_back(p.scored[t]);
      r.region.push_back(reg);
      r.x.emplace_back();
    }
    r.x.back().add(p.x[t] - x_mean, 0.0);
  }
  return r;
}

// One pass of He (fs, fd) over the probe: sums over the overall set and per region.
void accumulate(const Runs& runs, double fs, double fd, double phase_fraction, int regions,
                Sums& overall, std::vector<Sums>& per_region) {
  He he{fs, fd};
  he.reset(runs.uq.front(), phase_fraction * (fs - fd));
  overall = Sums{};
  per_region.assign(static_cast<std::size_t>(regions), Sums{});
  for (std::size_t i = 0; i < runs.uq.size(); ++i) {
    const double H = he.step(runs.uq[i]) - runs.centre;
    if (runs.scored[i]) overall.add_run(runs.x[i], H);
    if (runs.region[i] >= 0)
      per_region[static_cast<std::size_t>(runs.region[i])].add_run(runs.x[i], H);
  }
}

}  // namespace

StictionQuantification quantify_stiction(const HammersteinModel& model,
                                         const std::vector<double>& op,
                                         const StictionQuantificationOptions& opt) {
  const PreisachGrid& g = model.grid;
  if (static_cast<int>(model.mu.size()) != g.relay_count())
    throw std::invalid_argument("stiction quantification: the weights do not match the grid");
  const int R = std::max(1, opt.regions);
  const double delta = g.delta();
  StictionQuantification q;
  q.resolution_percent = delta;
  q.overall = q.preisach = unmeasured();

  // The visited range: the data's OP extremes, or the whole grid.
  double umin = std::numeric_limits<double>::infinity(), umax = -umin;
  std::size_t finite = 0;
  for (double u : op)
    if (std::isfinite(u)) {
      umin = std::min(umin, u);
      umax = std::max(umax, u);
      ++finite;
    }
  q.data_given = finite > 0;
  if (q.data_given) {
    q.op_lo = std::max(umin, g.umin);
    q.op_hi = std::min(umax, g.umax);
  } else {
    q.op_lo = g.umin;
    q.op_hi = g.umax;
  }
  const double width = std::max(0.0, q.op_hi - q.op_lo);
  q.regions.resize(static_cast<std::size_t>(R));
  for (int r = 0; r < R; ++r) {
    auto& reg = q.regions[static_cast<std::size_t>(r)];
    reg.op_lo = q.op_lo + width * r / R;
    reg.op_hi = q.op_lo + width * (r + 1) / R;
    reg.figures = reg.preisach = unmeasured();
    reg.visited = !q.data_given;
  }
  auto region_of = [&](double u) {
    if (!(width > 0)) return 0;
    return std::clamp(static_cast<int>(std::floor((u - q.op_lo) / width * R)), 0, R - 1);
  };

  double total_weight = 0;
  for (double w : model.mu) total_weight += w;
  const int levels = g.level(q.op_hi) - g.level(q.op_lo);
  if (levels < 2 || !(total_weight > 0)) {
    q.summary = levels < 2 ? "stiction not quantified: the data visited less than two levels of "
                             "the Preisach grid"
                           : "stiction not quantified: the valve model has no weights";
    return q;
  }
  q.valid = true;

  Probe p = q.data_given ? data_probe(model, op, width)
                         : forc_probe(model, g.level(q.op_lo), g.level(q.op_hi));
  // He sees the input as the Preisach model does, on the grid: the slips of both fall on the
  // same samples, and neither the offset of the samples from the thresholds nor the phase of the
  // grid shows up as a difference between the models.
  for (double u : p.u) p.uq.push_back(g.umin + g.level(u) * delta);
  for (double ru : p.reversal_u) q.regions[static_cast<std::size_t>(region_of(ru))].probes++;
  if (q.data_given) {
    for (double u : p.u) q.regions[static_cast<std::size_t>(region_of(u))].samples++;
    for (auto& reg : q.regions) {
      reg.data_reversals = reg.probes;
      reg.visited = static_cast<double>(reg.samples) >=
                        opt.min_region_sample_fraction * static_cast<double>(p.u.size()) &&
                    reg.data_reversals >= opt.min_region_reversals;
    }
  }
  double var_all = 0;
  {
    Sums s;
    for (std::size_t t = 0; t < p.u.size(); ++t)
      if (p.scored[t]) s.add(p.x[t], 0.0);
    var_all = s.var_p();
  }

  // Grid search over fs in [0, width], fd in [0, fs] and the staircase phase (a fraction of
  // fs - fd), then two finer grids around the best.
  struct Best {
    double fs = 0, fd = 0, phase = 0, cost = std::numeric_limits<double>::infinity();
  };
  // Costs this close are equal: the cost is flat up to rounding over a valley (the slips fall on
  // the same samples), and which point of it wins must not depend on the order of the sums.
  auto tie = [&](double c) { return std::isfinite(c) ? c * 1e-9 + 1e-12 * (1.0 + var_all) : 0.0; };
  auto search = [&](auto&& cost_of) {
    Best b;
    auto scan = [&](double fs0, double fs1, double fd0, double fd1, double step,
                    const std::vector<double>& phases) {
      for (double fs = std::max(0.0, fs0); fs <= fs1 + 1e-9 * step; fs += step)
        for (double fd = std::max(0.0, fd0); fd <= std::min(fs, fd1) + 1e-9 * step; fd += step)
          for (double ph : phases) {
            ph -= std::floor(ph);
            const double c = cost_of(fs, fd, ph);
            if (c < b.cost - tie(b.cost)) b = {fs, fd, ph, c};
          }
    };
    double step = std::max(delta / 4, width / 40);
    scan(0, width, 0, width, step, {0.0, 0.25, 0.5, 0.75});
    double dph = 0.125;
    for (int refine = 0; refine < 2; ++refine) {
      const Best c = b;
      scan(c.fs - step, c.fs + step, c.fd - step, c.fd + step, step / 4,
           {c.phase - dph, c.phase, c.phase + dph});
      step /= 4;
      dph /= 4;
    }
    // The input is on the grid, so the cost is flat over an interval of band and of jump (the
    // slips fall on the same samples): report the middle of the flat part, not its low end. The
    // band is known to a grid step, no better.
    const double tol = tie(b.cost);
    auto flat_part = [&](double dband, double djump, bool top) {
      double lo = 0, hi = 0;
      const double h = delta / 16;
      for (int sign : {-1, 1})
        for (int i = 1; i <= 16; ++i) {
          const double e = sign * i * h;
          const double f_s = b.fs + e * (dband + djump) / 2, f_d = b.fd + e * (dband - djump) / 2;
          if (f_d < 0 || f_s < f_d || !(cost_of(f_s, f_d, b.phase) <= b.cost + tol)) break;
          (sign < 0 ? lo : hi) = e;
        }
      return top ? hi : (lo + hi) / 2;
    };
    const double eb = flat_part(1, 0, false);
    b.fs += eb / 2;
    b.fd += eb / 2;
    const double ej = flat_part(0, 1, false);
    b.fs += ej / 2;
    b.fd -= ej / 2;
    b.cost = cost_of(b.fs, b.fd, b.phase);
    return b;
  };
  Sums sums;
  std::vector<Sums> per_region;
  const Runs overall_runs = runs_of(p, {}, opt.reuse_costs);
  const Best best = search([&](double f_s, double f_d, double ph) {
    accumulate(overall_runs, f_s, f_d, ph, R, sums, per_region);
    double s;
    return sums.cost_free(&s);
  });
  const double fs = best.fs, fd = best.fd, cost = best.cost;
  accumulate(overall_runs, fs, fd, best.phase, R, sums, per_region);
  sums.cost_free(&q.scale);
  q.overall = figures(fs, fd, cost, var_all);
  q.stiction = q.scale > 0 && q.overall.band_percent > delta;
  q.jump_identified = q.stiction && p.longest_sweep >= 2 * fs + delta;
  if (!q.stiction) {
    // No resolved band: He's best fit is a valve that follows the OP (up to the grid step).
    q.overall.fs_percent = q.overall.fd_percent = q.overall.band_percent = q.overall.jump_percent =
        0.0;
  }

  // Per region: the samples within a window after each turning point in the region (long enough
  // for the overall band and a slip or two), with the overall scale.
  const double window =
      std::min(width, (q.stiction ? 2 * q.overall.band_percent : 0.0) + 2 * delta);
  std::vector<int> region_of_sample(p.u.size(), -1);
  for (std::size_t t = 0; t < p.u.size(); ++t)
    if (p.scored[t] && p.reversal[t] >= 0 && p.since[t] <= window)
      region_of_sample[t] = region_of(p.reversal_u[static_cast<std::size_t>(p.reversal[t])]);
  const Runs region_runs = runs_of(p, region_of_sample, opt.reuse_costs);
  for (int r = 0; r < R; ++r) {
    auto& reg = q.regions[static_cast<std::size_t>(r)];
    reg.valid = reg.visited && reg.probes > 0;
    if (reg.probes == 0) continue;
    if (!(q.scale > 0)) {
      reg.figures = {0.0, 0.0, 0.0, 0.0, detail::kNaN};
      continue;
    }
    const Best rb = search([&](double f_s, double f_d, double ph) {
      accumulate(region_runs, f_s, f_d, ph, R, sums, per_region);
      return per_region[static_cast<std::size_t>(r)].cost_fixed(q.scale);
    });
    accumulate(region_runs, rb.fs, rb.fd, rb.phase, R, sums, per_region);
    if (per_region[static_cast<std::size_t>(r)].n < 2) {  // no sample after its reversals
      reg.valid = false;
      continue;
    }
    reg.figures = figures(rb.fs, rb.fd, rb.cost, per_region[static_cast<std::size_t>(r)].var_p());
    reg.stiction = reg.valid && reg.figures.band_percent > delta;
    if (reg.figures.band_percent <= delta)
      reg.figures.fs_percent = reg.figures.fd_percent = reg.figures.band_percent =
          reg.figures.jump_percent = 0.0;
  }

  q.summary = stiction_sentence(q);
  q.preisach = q.overall;
  for (auto& reg : q.regions) reg.preisach = reg.figures;
  return q;
}

}  // namespace valvediag
