#include "valvediag/model/model_spec.hpp"

#include <algorithm>
#include <iterator>

namespace valvediag {
namespace {

std::string_view trim(std::string_view s) {
  const auto first = s.find_first_not_of(" \t");
  if (first == std::string_view::npos) return {};
  const auto last = s.find_last_not_of(" \t");
  return s.substr(first, last - first + 1);
}

std::string vocabulary_text() {
  std::string s = "linear";
  for (const auto& e : effect_vocabulary()) {
    s += ", " + e.name;
    if (!e.variants.empty()) {
      s += " (";
      for (std::size_t i = 0; i < e.variants.size(); ++i) {
        if (i) s += '|';
        s += e.variants[i];
      }
      s += ")";
    }
  }
  return s;
}

std::size_t rank(const std::string& name) {
  const auto& v = effect_vocabulary();
  for (std::size_t i = 0; i < v.size(); ++i)
    if (v[i].name == name) return i;
  return v.size();
}

// Canonical order plus the combination rules the estimators rely on.
ModelSpec normalized(ModelSpec spec) {
  std::stable_sort(
      spec.effects.begin(), spec.effects.end(),
      [](const EffectSpec& a, const EffectSpec& b) { return rank(a.name) < rank(b.name); });
  for (std::size_t i = 1; i < spec.effects.size(); ++i) {
    if (spec.effects[i].name == spec.effects[i - 1].name)
      throw ModelSpecError("effect '" + spec.effects[i].name + "' appears twice in the model");
  }
  if (spec.has("preisach")) {
    for (const auto& e : spec.effects) {
      if (e.name != "preisach" && find_effect(e.name)->stage == EffectStage::Valve) {
        // The Preisach weights already represent any stiction, backlash, travel limit or
        // monotone static curve; a lag before the relays is not in the core's estimator.
        throw ModelSpecError("'preisach' cannot be combined with '" + e.name +
                             "': the Preisach model already represents stiction, deadband, "
                             "saturation and characteristic, and actuator-lag before it is not "
                             "supported; combine it with process effects only");
      }
    }
  }
  return spec;
}

}  // namespace

const std::vector<EffectInfo>& effect_vocabulary() {
  static const std::vector<EffectInfo> v = {
      {"actuator-lag", EffectStage::Valve, {}, "first-order actuator time constant tau"},
      {"stiction",
       EffectStage::Valve,
       {"he", "kano", "choudhury", "stenman"},
       "two-parameter stiction (He fs, fd; Kano or Choudhury S, J; Stenman d)"},
      {"deadband", EffectStage::Valve, {}, "backlash band d"},
      {"preisach",
       EffectStage::Valve,
       {"auto", "general", "position-dependent"},
       "hysteresis beyond two-parameter stiction: Preisach weights (general, the core method) "
       "or He's friction with one level below a valve position and another above it "
       "(position-dependent); auto fits both and keeps the better by BIC"},
      {"saturation", EffectStage::Valve, {}, "travel limits lower, upper"},
      {"characteristic",
       EffectStage::Valve,
       {"auto", "equal-percentage", "quick-opening"},
       "installed characteristic: rangeability R (auto: the curvature's sign picks the kind)"},
      {"delay", EffectStage::Process, {}, "dead time beyond the base nk range"},
      {"order", EffectStage::Process, {}, "ARX orders na, nb beyond the base range"},
      {"integrator", EffectStage::Process, {}, "integrating process: a fixed (1 - q^-1) in A"},
      {"disturbance", EffectStage::Process, {}, "slow unmeasured load: piecewise-linear drift"},
  };
  return v;
}

const EffectInfo* find_effect(std::string_view name) {
  for (const auto& e : effect_vocabulary())
    if (e.name == name) return &e;
  return nullptr;
}

bool is_valve_effect(std::string_view name) {
  const EffectInfo* info = find_effect(name);
  return info && info->stage == EffectStage::Valve;
}

bool is_lag_effect(std::string_view name) {
  return name == "actuator-lag" || name == "order";
}

bool is_memory_effect(std::string_view name) {
  return name == "stiction" || name == "deadband" || name == "preisach";
}

bool has_memory_effect(const ModelSpec& spec) {
  return std::any_of(spec.effects.begin(), spec.effects.end(),
                     [](const EffectSpec& e) { return is_memory_effect(e.name); });
}

bool has_valve_nonlinearity(const ModelSpec& spec) {
  return std::any_of(spec.effects.begin(), spec.effects.end(), [](const EffectSpec& e) {
    return is_valve_effect(e.name) && e.name != "actuator-lag";
  });
}

const EffectSpec* ModelSpec::find(std::string_view name) const {
  for (const auto& e : effects)
    if (e.name == name) return &e;
  return nullptr;
}

EffectSpec parse_effect(std::string_view text) {
  text = trim(text);
  const auto colon = text.find(':');
  const std::string name(trim(text.substr(0, colon)));
  const std::string variant(colon == std::string_view::npos ? std::string_view{}
                                                            : trim(text.substr(colon + 1)));
  if (name.empty()) throw ModelSpecError("empty effect name (known: " + vocabulary_text() + ")");
  const EffectInfo* info = find_effect(name);
  if (!info) {
    throw ModelSpecError("unknown effect '" + name + "' (known: " + vocabulary_text() + ")");
  }
  EffectSpec e{name, ""};
  if (colon != std::string_view::npos) {
    if (std::find(info->variants.begin(), info->variants.end(), variant) == info->variants.end()) {
      throw ModelSpecError("unknown variant '" + variant + "' of '" + name +
                           "' (known: " + vocabulary_text() + ")");
    }
    e.variant = variant;
  } else if (!info->variants.empty()) {
    e.variant = info->variants.front();
  }
  return e;
}

ModelSpec parse_model_spec(std::string_view text) {
  ModelSpec spec;
  if (trim(text).empty()) throw ModelSpecError("empty model (known: " + vocabulary_text() + ")");
  std::size_t pos = 0;
  while (true) {
    const auto plus = text.find('+', pos);
    const std::string_view part = trim(
        text.substr(pos, plus == std::string_view::npos ? std::string_view::npos : plus - pos));
    if (part != "linear") spec.effects.push_back(parse_effect(part));
    if (plus == std::string_view::npos) break;
    pos = plus + 1;
  }
  return normalized(std::move(spec));
}

std::string to_string(const EffectSpec& e) {
  const EffectInfo* info = find_effect(e.name);
  if (info && !info->variants.empty() && e.variant != info->variants.front())
    return e.name + ":" + e.variant;
  return e.name;
}

std::string to_string(const ModelSpec& spec) {
  if (spec.effects.empty()) return "linear";
  std::string s;
  for (const auto& e : spec.effects) {
    if (!s.empty()) s += '+';
    s += to_string(e);
  }
  return s;
}

bool preisach_generalizes(std::string_view name) {
  return name == "stiction" || name == "deadband";
}

ModelSpec add_effect(const ModelSpec& spec, std::string_view effect,
                     std::vector<EffectSpec>* replaced) {
  const EffectSpec e = parse_effect(effect);
  ModelSpec out = spec;
  std::vector<EffectSpec> gone;
  // What the added effect displaces: `preisach` takes the narrower frictions' place; any other
  // valve effect takes the Preisach model's (its weights combine with no other valve block: they
  // already represent friction, backlash, limits and curvature); the ladder keeps both fits.
  const bool valve = find_effect(e.name)->stage == EffectStage::Valve;
  const auto displaced = [&e, valve](const EffectSpec& h) {
    return e.name == "preisach" ? preisach_generalizes(h.name) : valve && h.name == "preisach";
  };
  std::copy_if(out.effects.begin(), out.effects.end(), std::back_inserter(gone), displaced);
  out.effects.erase(std::remove_if(out.effects.begin(), out.effects.end(), displaced),
                    out.effects.end());
  bool switched = false;
  for (auto& have : out.effects) {
    if (have.name != e.name) continue;
    if (have == e) throw ModelSpecError("'" + to_string(e) + "' is already in the model");
    have.variant = e.variant;
    switched = true;
  }
  if (!switched) out.effects.push_back(e);
  out = normalized(std::move(out));
  if (replaced) *replaced = std::move(gone);
  return out;
}

ModelSpec remove_effect(const ModelSpec& spec, std::string_view effect) {
  const std::string_view t = trim(effect);
  const bool with_variant = t.find(':') != std::string_view::npos;
  const EffectSpec e = parse_effect(t);
  ModelSpec out = spec;
  const auto it = std::find_if(out.effects.begin(), out.effects.end(), [&](const EffectSpec& h) {
    return h.name == e.name && (!with_variant || h.variant == e.variant);
  });
  if (it == out.effects.end()) {
    throw ModelSpecError("'" + std::string(t) + "' is not in the model '" + to_string(spec) + "'");
  }
  out.effects.erase(it);
  return out;
}

}  // namespace valvediag
