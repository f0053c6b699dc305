#include "valvediag/core/identifiability.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <map>
#include <set>
#include <sstream>

#include "valvediag/core/relay_design.hpp"

namespace valvediag {

const char* to_string(ExcitationKind k) {
  switch (k) {
    case ExcitationKind::General:
      return "general";
    case ExcitationKind::TwoExtremes:
      return "two-extremes";
    case ExcitationKind::Insufficient:
      return "insufficient";
  }
  return "unknown";
}

Identifiability analyse_identifiability(const PreisachGrid& grid, const std::vector<double>& u,
                                        const std::vector<int>& history) {
  Identifiability r;
  r.relays = grid.relay_count();
  if (u.size() < 3) {
    r.kind = ExcitationKind::Insufficient;
    r.summary = "too few samples to say anything about the valve weights";
    return r;
  }
  // Turning points of the virtual input (eq 23).
  std::vector<int> levels;
  for (double x : u) {
    const int v = grid.level(x);
    if (levels.empty() || levels.back() != v) levels.push_back(v);
  }
  std::vector<int> maxima, minima;
  for (std::size_t i = 1; i + 1 < levels.size(); ++i) {
    if (levels[i] > levels[i - 1] && levels[i] > levels[i + 1]) maxima.push_back(levels[i]);
    if (levels[i] < levels[i - 1] && levels[i] < levels[i + 1]) minima.push_back(levels[i]);
  }
  r.reversals = static_cast<int>(maxima.size() + minima.size());
  std::set<int> smax(maxima.begin(), maxima.end()), smin(minima.begin(), minima.end());
  r.distinct_maxima = static_cast<int>(smax.size());
  r.distinct_minima = static_cast<int>(smin.size());
  std::set<int> hit(smax);
  hit.insert(smin.begin(), smin.end());
  if (!levels.empty()) {
    hit.insert(*std::min_element(levels.begin(), levels.end()));
    hit.insert(*std::max_element(levels.begin(), levels.end()));
  }
  r.threshold_coverage = static_cast<double>(hit.size()) / (grid.L + 1);

  // Rank of the relay states with the constant: what the data can determine (merged columns).
  RelayDesignOptions o;
  o.max_lag = 0;
  o.max_na = 0;
  o.start = 0;
  o.end = u.size();
  std::vector<double> y(u.size(), 0.0);
  RelayDesign d(grid, u, y, history, o);
  r.distinct_histories = d.columns();
  r.switching_relays = 0;
  for (int c : d.column_of_relay()) r.switching_relays += c >= 0;
  Eigen::MatrixXd A(d.states(), d.columns() + 1);
  A.col(0).setOnes();
  A.rightCols(d.columns()) = d.gamma();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
  r.identifiable_combinations = std::max<int>(0, static_cast<int>(qr.rank()) - 1);

  // Proposition 3: nearly all reversals at one maximum and one minimum level (+-1 level).
  auto concentrated = [](const std::vector<int>& v) {
    if (v.empty()) return false;
    std::map<int, int> count;
    for (int x : v) ++count[x];
    int best = 0;
    for (const auto& [lvl, c] : count) {
      int near = c + (count.count(lvl - 1) ? count[lvl - 1] : 0) +
                 (count.count(lvl + 1) ? count[lvl + 1] : 0);
      best = std::max(best, near);
    }
    return best >= 0.8 * static_cast<double>(v.size());
  };
  std::ostringstream s;
  if (r.reversals < 2 || levels.size() < 3) {
    r.kind = ExcitationKind::Insufficient;
    s << "the input hardly reverses (" << r.reversals
      << " reversals): the valve's hysteresis is not excited and its weights are not identifiable";
  } else if (maxima.size() >= 2 && minima.size() >= 2 && concentrated(maxima) &&
             concentrated(minima)) {
    r.kind = ExcitationKind::TwoExtremes;
    // The paper's Proposition 3; user text names no paper numbers (docs/method.md has them).
    s << "the input oscillates between two extremes: only about 2L-1 = " << 2 * grid.L - 1
      << " combinations of the " << r.relays << " weights are identifiable ("
      << r.identifiable_combinations
      << " on this data); read the weights as the loop's ascending and descending paths, not one "
         "by one";
  } else {
    r.kind = ExcitationKind::General;
    // Lemma 1: every weight is identifiable when the extrema cover all thresholds.
    s << "the input reverses " << r.reversals << " times; its extrema cover "
      << static_cast<int>(100 * r.threshold_coverage + 0.5)
      << " % of the thresholds (every weight needs all); " << r.identifiable_combinations << " of "
      << r.relays << " weight combinations are identifiable";
  }
  r.summary = s.str();
  return r;
}

}  // namespace valvediag
