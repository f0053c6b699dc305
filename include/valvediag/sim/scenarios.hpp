// Named closed-loop scenarios: each a realistic loop showing one valve or process effect, plus
// the paper's Example 1. Scenarios can also be read from TOML files (configs/scenarios/*.toml;
// the keys are documented in the header of configs/scenarios/paper-ex1.toml).
#pragma once

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "valvediag/io/loop_data.hpp"
#include "valvediag/sim/loop_simulator.hpp"

namespace valvediag {

struct Scenario {
  std::string name;
  std::string description;  // one line: what the loop is and which effect it shows
  LoopConfig loop;          // Ts, controller, valve chain, process, disturbances, noise, set point
  std::size_t default_samples = 3000;
};

std::vector<std::string> scenario_names();
// Throws std::invalid_argument naming the known scenarios when `name` is not one of them.
Scenario scenario_by_name(const std::string& name);
// Simulates `samples` samples (0: the scenario's default_samples). LoopData::source is
// "scenario <name>, seed <seed>".
LoopData run_scenario(const Scenario& scenario, std::uint64_t seed, std::size_t samples);

// A run with the simulator's record of where each effect acted (LoopSimulator::activity).
struct ScenarioRun {
  LoopData data;
  std::vector<EffectActivity> activity;
  std::vector<double> valve_pv;  // LoopSimulator::valve_pv: PV without loads and noise
  const EffectActivity* find(const std::string& effect) const;  // nullptr when absent
};
ScenarioRun run_scenario_traced(const Scenario& scenario, std::uint64_t seed, std::size_t samples);

// A problem in a scenario file: the message reads "<file>:<line>:<column>: <key>: <what is
// wrong>; <what to do>", and the parts are available for tools.
class ScenarioFileError : public std::runtime_error {
 public:
  ScenarioFileError(std::string file, int line, int column, std::string key, std::string problem);
  const std::string& file() const { return file_; }
  int line() const { return line_; }               // 1-based, 0 when unknown
  int column() const { return column_; }           // 1-based, 0 when unknown
  const std::string& key() const { return key_; }  // e.g. "valve[2].fs", "" for syntax errors

 private:
  std::string file_;
  int line_, column_;
  std::string key_;
};

// Reads a scenario from a TOML file. Throws ScenarioFileError (file cannot be read, TOML syntax,
// missing, unknown or ill-typed key, or values the simulator rejects).
Scenario load_scenario_file(const std::string& path);
// The same from TOML text; `source_name` is used as the file name in messages.
Scenario parse_scenario_toml(std::string_view text, const std::string& source_name);
// Writes a scenario as TOML that parse_scenario_toml reads back to an identical simulation
// (numbers are written in shortest round-trip form).
std::string scenario_to_toml(const Scenario& scenario);

}  // namespace valvediag
