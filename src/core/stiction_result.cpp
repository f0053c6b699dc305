#include "stiction_result.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace valvediag::detail {
namespace {

double fit_percent(double cost, double var) {
  return var > 0 ? 100.0 * (1.0 - std::sqrt(cost / var)) : kNaN;
}

std::string pct(double v, int prec = 1) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", prec, v);
  return buf;
}

// "; the data fit fs a-b %, fd c-d % within 95 % (profile likelihood)", or "" without an interval.
std::string interval_clause(const StictionInterval& iv) {
  if (!iv.valid) return "";
  const std::string fs = iv.fs_open_above ? pct(iv.fs_lo) + " % or more (up to the OP span " +
                                                pct(iv.fs_hi) + " %: the data do not bound it)"
                                          : pct(iv.fs_lo) + "-" + pct(iv.fs_hi) + " %";
  return "; the data fit fs " + fs + ", fd " + pct(iv.fd_lo) + "-" + pct(iv.fd_hi) + " % within " +
         pct(100 * iv.level(), 0) + " % (profile likelihood" +
         (iv.capped ? ", at least that wide" : "") + ")";
}

}  // namespace

StictionFigures figures(double fs, double fd, double cost, double var) {
  return {fs, fd, fs + fd, fs - fd, fit_percent(cost, var)};
}

StictionFigures unmeasured() {
  return {kNaN, kNaN, kNaN, kNaN, kNaN};
}

std::string stiction_sentence(const StictionQuantification& q, const std::string& span) {
  if (!q.stiction && q.refined)
    return std::string("no stiction resolved: ") +
           (q.interval.valid && q.interval.fs_lo > 0
                ? "the band He's fit finds (" + pct(q.overall.band_percent, 2) +
                      " %) is below the grid step " + pct(q.resolution_percent) + " %" + span
                : std::string("a valve without stiction fits the data as well")) +
           interval_clause(q.interval);
  if (!q.stiction)
    return "no stiction resolved: the band is below the grid step " + pct(q.resolution_percent) +
           " %" + span;
  return "stiction: fs " + pct(q.overall.fs_percent) + " %, fd " + pct(q.overall.fd_percent) +
         " % of travel (band " + pct(q.overall.band_percent) + " %, slip jump " +
         pct(q.overall.jump_percent) + " %) over OP " + pct(q.op_lo) + "-" + pct(q.op_hi) +
         (span.empty() ? " %" : span) +
         (q.jump_identified || q.refined
              ? ""
              : "; the data's sweeps are too short to split the band into fs and fd") +
         interval_clause(q.interval);
}

}  // namespace valvediag::detail

namespace valvediag {

using detail::pct;
using detail::stiction_sentence;

StictionQuantification in_percent_of_span(StictionQuantification q, const OpRange& span) {
  const double op_lo = span.lo, op_hi = span.hi;
  if (!(std::isfinite(op_lo) && std::isfinite(op_hi) && op_lo < op_hi))
    throw std::invalid_argument("in_percent_of_span: needs op_lo < op_hi, both finite");
  const double k = 100.0 / (op_hi - op_lo);
  auto scale = [k](StictionFigures& f) {
    f.fs_percent *= k;  // NaN stays NaN
    f.fd_percent *= k;
    f.band_percent *= k;
    f.jump_percent *= k;
  };
  scale(q.overall);
  scale(q.preisach);
  for (auto& g : q.regions) {
    scale(g.figures);
    scale(g.preisach);
    g.fs_lo *= k;
    g.fs_hi *= k;
  }
  q.resolution_percent *= k;
  q.scale /= k;
  for (double* v : {&q.interval.fs_lo, &q.interval.fs_hi, &q.interval.fd_lo, &q.interval.fd_hi,
                    &q.interval.step_percent})
    *v *= k;
  if (q.valid) q.summary = stiction_sentence(q, " of the OP span " + pct(op_lo) + ":" + pct(op_hi));
  return q;
}

}  // namespace valvediag
