#include "valvediag/sweep/quiet_lead_in.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace valvediag {

QuietLeadIn quiet_lead_in(const std::vector<double>& op, const QuietLeadInOptions& opt) {
  QuietLeadIn q;
  const std::size_t N = op.size();
  q.departure = N;
  if (N < 2 * opt.min_samples || N < 20) return q;
  const auto [lo, hi] = std::minmax_element(op.begin(), op.end());
  const double span = *hi - *lo;
  if (!(span > 0) || !std::isfinite(span)) return q;
  // The starting level: a median, so that noise and a spike at the first sample do not move it.
  std::vector<double> head(op.begin(),
                           op.begin() + static_cast<long>(std::max<std::size_t>(10, N / 50)));
  const auto mid = head.begin() + static_cast<long>(head.size() / 2);
  std::nth_element(head.begin(), mid, head.end());
  const double level = *mid;
  std::size_t k = 0;
  while (k < N && std::abs(op[k] - level) <= opt.level_share * span) ++k;
  q.departure = k;
  if (static_cast<double>(k) <= opt.min_share * static_cast<double>(N)) return q;
  const auto pre = static_cast<std::size_t>(opt.pre_roll_share * static_cast<double>(N - k));
  q.begin = std::min(k - std::min(k, pre), N - opt.min_samples);
  return q;
}

LoopData drop_lead_in(const LoopData& d, std::size_t begin) {
  LoopData r = d;
  auto cut = [begin](std::vector<double>& v) {
    v.erase(v.begin(), v.begin() + static_cast<long>(std::min(begin, v.size())));
  };
  cut(r.t);
  cut(r.op);
  cut(r.pv);
  cut(r.sp);
  cut(r.mv);
  return r;
}

std::string describe_lead_in(const QuietLeadIn& q, const std::vector<double>& t, double origin) {
  if (!q.cut() || q.begin >= t.size()) return {};
  const double t0 = origin;
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "the analysis starts at t = %.0f s (sample %zu of %zu): before t = %.0f s OP "
                "holds within a quarter of its span of where it started, which shows nothing of "
                "the valve",
                t[q.begin] - t0, q.begin + 1, t.size(),
                t[std::min(q.departure, t.size() - 1)] - t0);
  return buf;
}

}  // namespace valvediag
