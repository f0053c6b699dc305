// Subcommands of the valvediag binary. Each registers itself on the app and returns the exit
// status through the shared Exit value.
#pragma once

#include <CLI/CLI.hpp>
#include <stdexcept>
#include <string>

namespace valvediag::cli {

// Exit statuses: findings and poor fits are results (0); these are the failures.
enum ExitCode : int { kOk = 0, kFailure = 1, kBadInput = 2, kNoModel = 3 };

// A user error found by a command (bad option combination, bad value): exit status 2.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

void add_fit(CLI::App& app, int& exit_code);
void add_simulate(CLI::App& app, int& exit_code);
void add_demo(CLI::App& app, int& exit_code);

}  // namespace valvediag::cli
