#include <doctest/doctest.h>

#include <string>
#include <vector>

#include "valvediag/model/model_spec.hpp"

using namespace valvediag;

TEST_CASE("model specs round-trip in canonical order") {
  for (const char* text :
       {"linear", "stiction", "stiction:kano", "stiction+saturation", "preisach+integrator",
        "actuator-lag+stiction:stenman+deadband+saturation+"
        "characteristic:quick-opening+delay+order+integrator+disturbance"}) {
    const ModelSpec s = parse_model_spec(text);
    CHECK(to_string(s) == text);
    CHECK(parse_model_spec(to_string(s)) == s);
  }
  // Written in another order, with spaces, defaults spelled out: the same model.
  const ModelSpec a = parse_model_spec(" saturation + stiction:he ");
  CHECK(to_string(a) == "stiction+saturation");
  CHECK(a == parse_model_spec("stiction+saturation"));
  REQUIRE(a.effects.size() == 2);
  CHECK(a.effects[0].variant == "he");
  CHECK(a.effects[1].variant.empty());
  CHECK(parse_model_spec("linear").effects.empty());
  CHECK(to_string(parse_model_spec("linear+deadband")) == "deadband");
  CHECK(to_string(parse_model_spec("characteristic")) == "characteristic");
  CHECK(parse_model_spec("characteristic").effects[0].variant == "auto");
}

TEST_CASE("unknown names and bad combinations are rejected with the vocabulary") {
  auto message = [](const char* text) {
    try {
      parse_model_spec(text);
    } catch (const ModelSpecError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string m = message("stiction+friction");
  CHECK(m.find("unknown effect 'friction'") != std::string::npos);
  for (const char* name : {"linear", "stiction", "deadband", "preisach", "saturation",
                           "characteristic", "actuator-lag", "delay", "order", "integrator",
                           "disturbance", "kano", "choudhury", "stenman"})
    CHECK_MESSAGE(m.find(name) != std::string::npos, name);
  CHECK(message("stiction:bogus").find("unknown variant 'bogus'") != std::string::npos);
  CHECK(message("delay:he").find("unknown variant") != std::string::npos);
  CHECK(message("stiction+stiction:kano").find("twice") != std::string::npos);
  CHECK(message("preisach+stiction").find("cannot be combined") != std::string::npos);
  CHECK(message("").find("empty model") != std::string::npos);
  CHECK(message("stiction++delay").find("empty effect name") != std::string::npos);
  CHECK_THROWS_AS(parse_model_spec("Stiction"), ModelSpecError);
  CHECK(message("preisach+delay+integrator") == "no error");
}

TEST_CASE("effects are added and removed relative to a spec") {
  const ModelSpec lin = parse_model_spec("linear");
  const ModelSpec st = add_effect(lin, "stiction");
  CHECK(to_string(st) == "stiction");
  const ModelSpec st_sat = add_effect(st, "saturation");
  CHECK(to_string(st_sat) == "stiction+saturation");
  CHECK(to_string(add_effect(st_sat, "actuator-lag")) == "actuator-lag+stiction+saturation");
  // Adding a variant switches it; adding what is there already is an error.
  CHECK(to_string(add_effect(st_sat, "stiction:kano")) == "stiction:kano+saturation");
  CHECK_THROWS_AS(add_effect(st_sat, "stiction"), ModelSpecError);
  CHECK_THROWS_AS(add_effect(st_sat, "friction"), ModelSpecError);
  CHECK(to_string(remove_effect(st_sat, "stiction")) == "saturation");
  CHECK(to_string(remove_effect(remove_effect(st_sat, "saturation"), "stiction")) == "linear");
  CHECK_THROWS_AS(remove_effect(st_sat, "deadband"), ModelSpecError);
  CHECK_THROWS_AS(remove_effect(st_sat, "stiction:kano"), ModelSpecError);
  CHECK(to_string(remove_effect(parse_model_spec("stiction:kano"), "stiction:kano")) == "linear");
  CHECK(to_string(add_effect(parse_model_spec("preisach"), "integrator")) == "preisach+integrator");
}

TEST_CASE("the valve effects with memory are stiction, deadband and preisach") {
  for (const auto& e : effect_vocabulary()) {
    CAPTURE(e.name);
    const bool memory = e.name == "stiction" || e.name == "deadband" || e.name == "preisach";
    CHECK(is_memory_effect(e.name) == memory);
  }
  CHECK(has_memory_effect(parse_model_spec("stiction:kano+saturation")));
  CHECK(has_memory_effect(parse_model_spec("deadband+integrator")));
  CHECK_FALSE(has_memory_effect(parse_model_spec("saturation+characteristic+disturbance")));
  CHECK_FALSE(has_memory_effect(parse_model_spec("linear")));
}

TEST_CASE("preisach replaces the stiction or deadband it generalizes, and says what it replaced") {
  std::vector<EffectSpec> replaced;
  const ModelSpec st = parse_model_spec("stiction:kano+integrator");
  const ModelSpec pr = add_effect(st, "preisach", &replaced);
  CHECK(to_string(pr) == "preisach+integrator");
  REQUIRE(replaced.size() == 1);
  CHECK(replaced[0].name == "stiction");
  CHECK(replaced[0].variant == "kano");
  CHECK(to_string(replaced[0]) == "stiction:kano");
  // Without the out-parameter, the same spec.
  CHECK(add_effect(st, "preisach") == pr);
  CHECK(to_string(add_effect(parse_model_spec("deadband+delay"), "preisach", &replaced)) ==
        "preisach+delay");
  REQUIRE(replaced.size() == 1);
  CHECK(replaced[0].name == "deadband");
  // Both narrower effects at once go together, in chain order.
  CHECK(to_string(add_effect(parse_model_spec("stiction+deadband"), "preisach", &replaced)) ==
        "preisach");
  REQUIRE(replaced.size() == 2);
  CHECK(replaced[0].name == "stiction");
  CHECK(replaced[1].name == "deadband");
  // A variant of preisach replaces them the same way, and is kept.
  CHECK(to_string(add_effect(st, "preisach:position-dependent")) ==
        "preisach:position-dependent+integrator");
  CHECK(parse_effect("preisach").variant == "auto");
  CHECK(to_string(parse_model_spec("preisach:auto")) == "preisach");
  CHECK(to_string(parse_model_spec("preisach:general+delay")) == "preisach:general+delay");
  // Nothing to replace: the list is emptied, not left from the last call.
  CHECK(to_string(add_effect(parse_model_spec("linear"), "preisach", &replaced)) == "preisach");
  CHECK(replaced.empty());
  CHECK(to_string(add_effect(parse_model_spec("stiction"), "saturation", &replaced)) ==
        "stiction+saturation");
  CHECK(replaced.empty());
}

TEST_CASE("preisach beside what it does not generalize throws; a valve effect on it replaces it") {
  auto message = [](const char* spec, const char* effect) {
    try {
      add_effect(parse_model_spec(spec), effect);
    } catch (const ModelSpecError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  // A valve effect on a Preisach model takes its place, and says what it replaced.
  {
    std::vector<EffectSpec> gone;
    CHECK(to_string(add_effect(parse_model_spec("preisach+integrator"), "stiction", &gone)) ==
          "stiction+integrator");
    REQUIRE(gone.size() == 1);
    CHECK(gone[0].name == "preisach");
    CHECK(to_string(add_effect(parse_model_spec("preisach"), "deadband")) == "deadband");
    CHECK(to_string(add_effect(parse_model_spec("preisach"), "stiction:stenman")) ==
          "stiction:stenman");
    CHECK(to_string(add_effect(parse_model_spec("preisach:general+delay"), "saturation", &gone)) ==
          "saturation+delay");
    CHECK(gone.size() == 1);
    CHECK(message("preisach", "actuator-lag") == "no error");
    // A process effect stays beside it.
    CHECK(to_string(add_effect(parse_model_spec("preisach"), "order", &gone)) == "preisach+order");
    CHECK(gone.empty());
  }
  // Stiction replaced, saturation stays: not combinable, and the spec is left as it was.
  std::vector<EffectSpec> replaced{EffectSpec{"order", ""}};
  const ModelSpec st_sat = parse_model_spec("stiction+saturation");
  CHECK_THROWS_AS(add_effect(st_sat, "preisach", &replaced), ModelSpecError);
  CHECK(message("stiction+saturation", "preisach").find("cannot be combined with 'saturation'") !=
        std::string::npos);
  CHECK(replaced.size() == 1);  // untouched when the addition fails
  CHECK(message("preisach", "preisach") == "'preisach' is already in the model");
  CHECK(preisach_generalizes("stiction"));
  CHECK(preisach_generalizes("deadband"));
  CHECK_FALSE(preisach_generalizes("saturation"));
  CHECK_FALSE(preisach_generalizes("preisach"));
}
