#include <doctest/doctest.h>

#include <string>

#include "valvediag/model_spec.hpp"

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
  CHECK_THROWS_AS(add_effect(st, "preisach"), ModelSpecError);
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
