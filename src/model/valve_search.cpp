#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "valvediag/model/effect_estimators.hpp"

namespace valvediag {
namespace {

const double kLnRMax = std::log(200.0);
constexpr double kLinearCurvature = 1e-3;

template <class... F>
struct Overload : F... {
  using F::operator()...;
};
template <class... F>
Overload(F...) -> Overload<F...>;

}  // namespace

InputRange input_range(const std::vector<double>& u, double Ts) {
  if (u.empty()) return {0.0, 0.0, Ts, 0.0, 0.0};
  const auto [lo, hi] = std::minmax_element(u.begin(), u.end());
  std::vector<double> v(u);
  const auto at = [&v](double q) {  // rank truncated, as the benchmark figures were measured
    const auto k = static_cast<std::ptrdiff_t>(q * static_cast<double>(v.size() - 1));
    std::nth_element(v.begin(), v.begin() + k, v.end());
    return v[static_cast<std::size_t>(k)];
  };
  const double w_lo = at(0.05), w_hi = at(0.95);
  return {*lo, *hi, Ts, w_lo, w_hi};
}

std::vector<SearchParameter> search_parameters(const EffectSpec& e, const InputRange& r) {
  const double R = std::max(r.umax - r.umin, 1e-9);
  if (e.name == "stiction") {
    if (e.variant == "he" || e.variant.empty())
      return {{"fs", "OP", 0.0, R}, {"fd/fs", "", 0.0, 1.0}, {"motion at start", "", -1.0, 1.0, 3}};
    if (e.variant == "kano" || e.variant == "choudhury")
      return {{"S", "OP", 0.0, R}, {"J/S", "", 0.0, 1.0}};
    if (e.variant == "stenman") return {{"d", "OP", 0.0, R}};
    throw std::invalid_argument("stiction: unknown variant '" + e.variant + "'");
  }
  if (e.name == "deadband") return {{"d", "OP", 0.0, R}};
  if (e.name == "saturation")
    return {{"lower", "OP", r.umin, r.umax - R / 100}, {"upper share", "", 0.01, 1.0}};
  if (e.name == "characteristic") {
    if (e.variant == "auto" || e.variant.empty()) return {{"curvature", "", -kLnRMax, kLnRMax}};
    return {{"ln R", "", kLinearCurvature, kLnRMax}};
  }
  if (e.name == "actuator-lag") return {{"tau", "s", 0.0, 60.0 * r.Ts}};
  // `order`: an extra first-order lag between the valve and the process, searched like the
  // actuator's (a chain of lags is what more ARX orders stand for; least squares alone fits
  // high orders poorly under coloured noise).
  if (e.name == "order") return {{"lag", "s", 0.0, 60.0 * r.Ts}};
  if (e.name == "preisach" && e.variant == "position-dependent")
    return {{"fs", "OP", 0.0, R},
            {"mild side", "", -1.0, 1.0},
            {"fd/fs", "", 0.0, 1.0},
            {"position", "OP", r.lo(), r.hi()},
            {"motion at start", "", -1.0, 1.0, 3},
            {"transition", "", 0.02, 1.0},
            {"fd/fs below less above", "", -1.0, 1.0}};
  if (find_effect(e.name)) return {};
  throw std::invalid_argument("unknown effect '" + e.name + "'");
}

ValveEffect make_valve_block(const EffectSpec& e, const double* th, const InputRange& r) {
  if (e.name == "stiction") {
    const double band = std::max(th[0], 0.0);
    if (e.variant == "stenman") return StenmanStiction(band);
    const double ratio = std::clamp(th[1], 0.0, 1.0);
    if (e.variant == "kano") return KanoStiction(band, ratio * band);
    if (e.variant == "choudhury") return ChoudhuryStiction(band, ratio * band);
    // The motion at the start is one of three states (down, rest, up): a continuous coordinate
    // would be a flat direction for the polish and let it trade the start for the bands.
    return HeStiction(band, ratio * band, std::round(std::clamp(th[2], -1.0, 1.0)));
  }
  if (e.name == "deadband") return Deadband(std::max(th[0], 0.0));
  if (e.name == "saturation") {
    // upper = lower + share (umax - lower): every lower < upper inside the OP range.
    const double upper = th[0] + std::clamp(th[1], 0.01, 1.0) * (r.umax - th[0]);
    return Saturation(th[0], std::max(upper, th[0] + 1e-9));
  }
  if (e.name == "characteristic") {
    const bool fixed = !(e.variant == "auto" || e.variant.empty());
    const double k = th[0];
    if (!fixed && std::abs(k) < kLinearCurvature)
      return Characteristic(Characteristic::Kind::linear, 2.0);
    Characteristic::Kind kind =
        k > 0 ? Characteristic::Kind::equal_percentage : Characteristic::Kind::quick_opening;
    if (fixed) kind = characteristic_kind_from_string(e.variant);
    return Characteristic(kind, std::exp(std::max(std::abs(k), kLinearCurvature)));
  }
  if (is_lag_effect(e.name)) return ActuatorLag(std::max(th[0], 0.0), r.Ts);
  if (e.name == "preisach" && e.variant == "position-dependent") {
    const double fs = std::max(th[0], 0.0), c = std::clamp(th[1], -1.0, 1.0);
    // fd/fs above the change, and below it that plus th[6]: each side its own kinetic share
    // (one share for both fitted the severe side's jump and distorted the mild side's band).
    const double ratio = std::clamp(th[2], 0.0, 1.0);
    const double ratio_below = std::clamp(th[2] + th[6], 0.0, 1.0);
    const double half = std::max(std::clamp(th[5], 0.02, 1.0) * (r.hi() - r.lo()) / 2.0, 1e-6);
    const double below = c > 0 ? (1.0 - c) * fs : fs, above = c < 0 ? (1.0 + c) * fs : fs;
    return PositionDependentStiction(
        {{th[3] - half, below, ratio_below * below}, {th[3] + half, above, ratio * above}},
        std::round(std::clamp(th[4], -1.0, 1.0)));
  }
  throw std::invalid_argument("effect '" + e.name + "' has no valve block to search");
}

std::vector<NamedValue> block_parameters(const ValveEffect& block) {
  return std::visit(
      Overload{[](const HeStiction& b) -> std::vector<NamedValue> {
                 return {{"fs", b.fs(), "OP"},
                         {"fd", b.fd(), "OP"},
                         {"initial_motion", b.initial_motion(), ""}};
               },
               [](const KanoStiction& b) -> std::vector<NamedValue> {
                 return {{"S", b.S(), "OP"}, {"J", b.J(), "OP"}};
               },
               [](const ChoudhuryStiction& b) -> std::vector<NamedValue> {
                 return {{"S", b.S(), "OP"}, {"J", b.J(), "OP"}};
               },
               [](const StenmanStiction& b) -> std::vector<NamedValue> {
                 return {{"d", b.d(), "OP"}};
               },
               [](const Deadband& b) -> std::vector<NamedValue> {
                 return {{"d", b.d(), "OP"}};
               },
               [](const Saturation& b) -> std::vector<NamedValue> {
                 return {{"lower", b.lower(), "OP"}, {"upper", b.upper(), "OP"}};
               },
               [](const Characteristic& b) -> std::vector<NamedValue> {
                 // curvature: ln R, negative for quick-opening (the search's k)
                 if (b.kind() == Characteristic::Kind::linear)
                   return {{"R", 1.0, ""}, {"curvature", 0.0, ""}};
                 const double k = std::log(b.rangeability());
                 return {
                     {"R", b.rangeability(), ""},
                     {"curvature", b.kind() == Characteristic::Kind::quick_opening ? -k : k, ""}};
               },
               [](const ActuatorLag& b) -> std::vector<NamedValue> {
                 return {{"tau", b.tau(), "s"}};
               },
               [](const PositionDependentStiction& b) -> std::vector<NamedValue> {
                 // fs, fd: where the valve sticks most (what its stiction figures count);
                 // the other side's as fs_mild, fd_mild; `position` where friction changes.
                 const auto& p = b.points();
                 const auto by_fs = [](const auto& x, const auto& y) { return x.fs < y.fs; };
                 const auto severe = std::max_element(p.begin(), p.end(), by_fs);
                 const auto mild = std::min_element(p.begin(), p.end(), by_fs);
                 return {{"fs", severe->fs, "OP"},
                         {"fd", severe->fd, "OP"},
                         {"fs_mild", mild->fs, "OP"},
                         {"fd_mild", mild->fd, "OP"},
                         {"position", (p.front().position + p.back().position) / 2.0, "OP"},
                         {"transition", p.back().position - p.front().position, "OP"},
                         {"severe_above", severe > mild ? 1.0 : 0.0, ""},
                         {"initial_motion", b.initial_motion(), ""}};
               },
               [](const auto&) -> std::vector<NamedValue> { return {}; }},
      block);
}

}  // namespace valvediag
