// Composable loop models: a chain of named effects (../shared/design/effects.md; the names are
// product interface) starting from `linear` (x = u).
//
//   OP u -> valve effects -> valve position x -> process effects -> PV y
//
// A spec is written as effect names joined by '+', each optionally with a variant after ':', e.g.
// `stiction+saturation`, `stiction:kano`, `preisach+integrator`, `linear`. Specs are kept in one
// canonical order (the physical order of the chain, below), so `saturation+stiction` and
// `stiction+saturation` are the same model and print the same way.
#pragma once

#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace valvediag {

enum class EffectStage { Valve, Process };

struct EffectInfo {
  std::string name;
  EffectStage stage;
  std::vector<std::string> variants;  // first = default; empty: the effect has no variants
  std::string summary;                // one line, what the estimator fits
};

// The vocabulary in canonical chain order: actuator-lag, stiction, deadband, preisach,
// saturation, characteristic (valve), then delay, order, integrator, disturbance (process).
// `linear` is not an effect: it names the empty chain.
const std::vector<EffectInfo>& effect_vocabulary();
// nullptr when unknown.
const EffectInfo* find_effect(std::string_view name);

// A bad spec: unknown name or variant, duplicate, or a combination the estimators cannot fit.
// The message lists the vocabulary where that helps.
class ModelSpecError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

struct EffectSpec {
  std::string name;
  std::string variant;  // always filled for effects with variants (the default when not given)
  bool operator==(const EffectSpec&) const = default;
};

struct ModelSpec {
  std::vector<EffectSpec> effects;  // canonical order, each name at most once; empty = linear

  bool has(std::string_view name) const { return find(name) != nullptr; }
  const EffectSpec* find(std::string_view name) const;
  bool operator==(const ModelSpec&) const = default;
};

// An effect of the valve stage (actuator-lag, stiction, deadband, preisach, saturation,
// characteristic: what the valve position x carries); false for process effects and unknown names.
bool is_valve_effect(std::string_view name);
// actuator-lag or order: a first-order lag block (ActuatorLag), before the valve effects or after
// them.
bool is_lag_effect(std::string_view name);
// Valve effects with memory (stiction, deadband, preisach): the valve's position depends on the
// path OP took, not on its present value alone.
bool is_memory_effect(std::string_view name);
bool has_memory_effect(const ModelSpec& spec);
// A valve effect other than actuator-lag (the one linear valve effect): without one, an
// actuator lag commutes with the process lags and no OP/PV record can place it in the valve.
bool has_valve_nonlinearity(const ModelSpec& spec);

// Parses "linear", "stiction", "stiction:kano+saturation", ... (spaces around names ignored).
// Throws ModelSpecError.
ModelSpec parse_model_spec(std::string_view text);
// "effect" or "effect:variant"; default variants are left out ("stiction", "stiction:kano").
EffectSpec parse_effect(std::string_view text);
// Canonical text: "linear" for the empty chain, default variants left out.
std::string to_string(const ModelSpec& spec);
std::string to_string(const EffectSpec& effect);

// The spec with `effect` ("name" or "name:variant") added. Adding an effect that is present with
// another variant switches the variant; adding one already present as given throws.
// The hysteresis effects nest: `preisach` generalizes `stiction` and `deadband` (the paper's
// Proposition 1: He's stiction is a Preisach model; so is a backlash), so adding `preisach` to a
// model with either REPLACES it (both, when both are there). The other way, any valve effect
// (`stiction`, `deadband`, `saturation`, `characteristic`, `actuator-lag`) added to a model with
// `preisach` replaces `preisach`: its weights combine with no other valve block. `replaced`,
// when given, receives what was taken out (empty when nothing was). Adding `preisach` beside
// `saturation`, `characteristic` or `actuator-lag` throws, as in parse_model_spec: remove them
// first.
ModelSpec add_effect(const ModelSpec& spec, std::string_view effect,
                     std::vector<EffectSpec>* replaced = nullptr);
// The effects `preisach` replaces when added (stiction, deadband).
bool preisach_generalizes(std::string_view name);
// The spec without the effect named (a variant, if given, must match). Throws when absent.
ModelSpec remove_effect(const ModelSpec& spec, std::string_view effect);

}  // namespace valvediag
