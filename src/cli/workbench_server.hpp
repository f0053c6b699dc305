// The workbench's HTTP server (cmd_serve.cpp), for `serve` and `demo --serve`.
#pragma once

#include <string>
#include <vector>

#include "valvediag/core/op_range.hpp"
#include "valvediag/serve/workbench_api.hpp"

namespace valvediag::cli {

struct WorkbenchSettings {
  int port = 8080;
  std::string bind = "127.0.0.1";
  bool token = false;         // a random token required on every request
  unsigned jobs = 0;          // model jobs at once; 0: one per core
  double validate = 0.3;      // the verdict's and the models' held-out share
  double min_gain = 2.0;      // the verdict's --min-gain
  bool keep_lead_in = false;  // analyse the whole record
  OpRange range;
};

// A UsageError when `bind` lets other machines in without a token.
void check_workbench_bind(const WorkbenchSettings& w);
// A loop to serve: `d` as read, the models fitted to the part diagnose analyses (notes say where
// it starts).
serve::ServedLoop served_loop(std::string name, LoopData d, const WorkbenchSettings& w,
                              std::vector<std::string>& notes);
// Serves the loops until Ctrl-C or SIGTERM, printing the address; throws when it cannot listen.
void run_workbench(std::vector<serve::ServedLoop> loops, const WorkbenchSettings& w);

}  // namespace valvediag::cli
