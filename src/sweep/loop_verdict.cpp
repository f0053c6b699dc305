#include "valvediag/sweep/loop_verdict.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include "valvediag/core/stiction_quantification.hpp"
#include "valvediag/diagnose/valve_travel.hpp"
#include "valvediag/diagnose/verdict.hpp"
#include "valvediag/diagnose/whole_record_test.hpp"

namespace valvediag {

namespace {

double param(const std::vector<NamedValue>& p, const char* name) {
  for (const auto& v : p)
    if (v.name == name) return v.value;
  return FrictionSize::kNaN;
}

}  // namespace

// A friction effect's band and jump in OP units from its parameters (NaN for other effects).
std::pair<double, double> band_and_jump(const std::string& effect,
                                        const std::vector<NamedValue>& p) {
  constexpr double kNaN = FrictionSize::kNaN;
  // Position-dependent friction (preisach) gives He's figures where the valve sticks most.
  if (effect == "stiction" || (effect == "preisach" && !std::isnan(param(p, "fs")))) {
    if (!std::isnan(param(p, "fs"))) return {param(p, "fs"), param(p, "fs") - param(p, "fd")};
    if (!std::isnan(param(p, "S"))) return {param(p, "S"), param(p, "J")};
    return {param(p, "d"), param(p, "d")};
  }
  if (effect == "deadband") return {param(p, "d"), 0.0};
  return {kNaN, kNaN};
}

// The friction figures of the fitted valve, in OP units: He (fs, fs - fd), Kano (S, J),
// Stenman (d: band, jump d), deadband (d, no jump), position-dependent friction (He's figures
// where it sticks most); a Preisach valve through He's figures fitted
// to its response on the data's own OP (stiction_quantification.hpp).
FrictionSize friction_size(const ModelFit& fit, const std::vector<double>& op,
                           const std::vector<double>& pv, const OpRange& range, int threads,
                           const std::optional<FitSetting>& setting) {
  const double width = std::max(range.hi - range.lo, 1e-12);
  FrictionSize a;
  if (fit.preisach) {
    StictionQuantificationOptions opt;
    opt.threads = threads;
    const StictionQuantification q = pv.size() == op.size()
                                         ? quantify_stiction(*fit.preisach, op, pv, opt)
                                         : quantify_stiction(*fit.preisach, op, opt);
    if (q.valid && q.stiction) {
      a.band_percent = q.overall.fs_percent * 100.0 / width;
      a.jump_percent = q.overall.jump_percent * 100.0 / width;
      if (q.interval.valid) {
        a.band_lo_percent = q.interval.fs_lo * 100.0 / width;
        a.band_hi_percent = q.interval.fs_hi * 100.0 / width;
        a.band_hi_open = q.interval.fs_open_above;
      }
    } else if (q.valid) {
      a.band_percent = 0.0;
      a.jump_percent = 0.0;
    }
  }
  std::string sized;  // the effect the band comes from
  for (const auto& e : fit.effects) {
    if (e.name == "deadband" && !std::isnan(a.band_percent)) continue;
    const auto [band, jump] = band_and_jump(e.name, e.parameters);
    if (std::isnan(band)) continue;
    a.band_percent = 100.0 * band / width;
    a.jump_percent = 100.0 * jump / width;
    a.band_lo_percent = a.band_hi_percent = FrictionSize::kNaN;  // not the Preisach valve's
    a.band_hi_open = false;
    sized = e.name;
  }
  if (!sized.empty() && setting && pv.size() == op.size()) {  // the band's range
    const BandInterval iv = band_interval(op, pv, setting->Ts, fit, sized, setting->options);
    if (iv.valid) {
      a.band_lo_percent = 100.0 * iv.lo / width;
      a.band_hi_percent = 100.0 * iv.hi / width;
      a.band_hi_open = iv.open_above;
    }
  }
  return a;
}

FrictionSize friction_size(const Diagnosis& d, const std::vector<double>& op,
                           const std::vector<double>& pv, const OpRange& range, int threads,
                           const std::optional<FitSetting>& setting) {
  const ValveTravel& t = d.valve_travel;  // measured position: its figures, or no friction
  if (t.decided && t.verdict == "no-valve-problem") return {};
  if (t.decided && std::isfinite(t.fs_percent)) return {t.fs_percent, t.jump_percent};
  FrictionSize a = friction_size(d.last().fit, op, pv, range, threads, setting);
  if (std::isnan(a.band_percent) && d.whole_record.confirmed) {
    ModelFit whole;  // the friction figures of the whole-record memory fit
    whole.effects = d.whole_record.memory_effects;
    std::optional<FitSetting> whole_setting;
    if (setting && !d.whole_record.memory_coordinates.empty()) {  // and the band's range
      whole.spec = parse_model_spec(d.whole_record.memory_model);
      whole.valve_coordinates = d.whole_record.memory_coordinates;
      whole_setting = FitSetting{setting->Ts, whole_record_fit_options(setting->options)};
    }
    a = friction_size(whole, op, pv, range, threads, whole_setting);
  }
  if (std::isnan(a.band_percent) && verdict(d) == "stiction" && d.limit_cycle.stick_slip)
    a.band_percent = 100.0 * d.limit_cycle.apparent_band / std::max(range.hi - range.lo, 1e-12);
  // The climb adds each step's first finding; a friction of the final model that a refit to the
  // prediction ranked there carries that refit's figures too.
  const ModelSpec& final_model = d.last().fit.spec;
  for (std::size_t k = 0; k + 1 < d.steps.size(); ++k) {
    if (d.steps[k].findings.empty()) continue;
    const Finding& f = d.steps[k].findings.front();
    if (f.prediction_parameters.empty() || !final_model.has(f.effect)) continue;
    const auto [band, jump] = band_and_jump(f.effect, f.prediction_parameters);
    if (std::isnan(band)) continue;
    const double width = std::max(range.hi - range.lo, 1e-12);
    a.prediction_band_percent = 100.0 * band / width;
    a.prediction_jump_percent = 100.0 * jump / width;
  }
  return a;
}

std::vector<SplitVerdict> split_verdicts(const LoopData& d, const DiagnoseOptions& opt,
                                         const std::vector<double>& splits, bool climb,
                                         const ModelSpec& start) {
  std::vector<SplitVerdict> out;
  for (const double v : splits) {
    DiagnoseOptions other = opt;
    other.validation_fraction = v;
    other.fit.validation_fraction = 0.0;  // the share above counts, not one fixed in fit options
    other.fit.validation_start = 0;
    SplitVerdict sv{v, ""};
    try {
      const double Ts = d.sample_period();
      sv.verdict = verdict(climb ? diagnose_auto(d.op, d.pv, d.mv, Ts, start, other)
                                 : diagnose(d.op, d.pv, d.mv, Ts, start, other));
    } catch (const std::invalid_argument&) {
      sv.verdict = "error";  // a share that leaves too little to fit: it does not confirm
    }
    out.push_back(sv);
  }
  return out;
}

std::pair<int, int> split_agreement(const std::string& verdict,
                                    const std::vector<SplitVerdict>& splits) {
  int agree = 1;
  for (const auto& v : splits) agree += v.verdict == verdict;
  return {agree, 1 + static_cast<int>(splits.size())};
}

QuietLeadIn lead_in_left_out(const LoopData& d, const VerdictOptions& opt, bool whole_usable) {
  if (opt.keep_lead_in) return {};
  QuietLeadInOptions q;
  q.min_samples = opt.min_samples;
  const QuietLeadIn lead = quiet_lead_in(d.op, q);
  if (!lead.cut() || !whole_usable) return lead;
  // The part must pass the usability checks by itself. When only the lead-in makes the record
  // usable (OP reverses there, within its quarter of the span, and not after), the lead-in
  // carries what the diagnosis needs: it is not quiet, so keep the whole record.
  const LoopData part = drop_lead_in(d, lead.begin);
  if (!unusable_reason(part, loop_health(part, opt.range), opt.min_samples).empty()) return {};
  return lead;
}

LoopVerdict loop_verdict(const LoopData& d, const VerdictOptions& opt) {
  LoopVerdict v;
  v.health = loop_health(d, opt.range);
  v.reason = unusable_reason(d, v.health, opt.min_samples);
  if (!v.reason.empty()) {
    v.verdict = "not-enough-data";
    return v;
  }
  v.lead_in = lead_in_left_out(d, opt, true);  // the whole record passed the check above
  const QuietLeadIn& lead = v.lead_in;
  const LoopData part = lead.cut() ? drop_lead_in(d, lead.begin) : LoopData{};
  const LoopData& x = lead.cut() ? part : d;  // what the diagnosis sees
  if (lead.cut()) v.analysed_from_s = d.t[lead.begin] - d.t.front();
  DiagnoseOptions dopt = opt.diagnose;
  dopt.candidates.clear();  // a verdict weighs every effect, whatever a command shows
  dopt.valve_travel.op_range = opt.range;
  dopt.time_origin_s += v.analysed_from_s;  // the reason's times on the caller's axis
  Diagnosis dg;
  try {
    dg = diagnose_auto(x.op, x.pv, x.mv, x.sample_period(), ModelSpec{}, dopt);
  } catch (const std::invalid_argument& e) {
    // The usability checks passed, so this is not the data's fault: say so, do not guess.
    v.verdict = "error";
    v.error = std::string("the diagnosis failed: ") + e.what();
    return v;
  }
  v.verdict = verdict(dg);
  v.model = to_string(dg.last().fit.spec);
  v.stiction = friction_size(dg, x.op, x.pv, opt.range, opt.diagnose.fit.threads,
                             FitSetting{x.sample_period(), fit_options(dopt)});
  v.reason = dg.conclusion;
  if (lead.cut()) {
    std::string s = describe_lead_in(lead, d.t, d.t.front() - opt.diagnose.time_origin_s);
    s[0] = static_cast<char>(std::toupper(static_cast<unsigned char>(s[0])));
    v.reason = s + ". " + v.reason;
  }
  v.split_verdicts = split_verdicts(x, dopt, opt.check_splits);
  v.diagnosis = std::move(dg);
  return v;
}

}  // namespace valvediag
