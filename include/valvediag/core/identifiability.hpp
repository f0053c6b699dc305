// What the data can tell about the Preisach weights (paper section 5).
#pragma once

#include <string>
#include <vector>

#include "valvediag/core/preisach.hpp"

namespace valvediag {

enum class ExcitationKind { General, TwoExtremes, Insufficient };
const char* to_string(ExcitationKind k);

struct Identifiability {
  ExcitationKind kind = ExcitationKind::General;
  int relays = 0;                     // K = L(L+1)/2
  int switching_relays = 0;           // relays that switch at least once on the data
  int distinct_histories = 0;         // merged columns
  int identifiable_combinations = 0;  // rank of the relay states (less the constant)
  int reversals = 0;                  // direction changes of the virtual input
  int distinct_maxima = 0, distinct_minima = 0;
  double threshold_coverage = 0.0;  // fraction of thresholds hit by a local extremum (Lemma 1)
  std::string summary;              // one plain sentence for the report
};

// Analyses the virtual input of u on the grid (levels before the first sample in `history`).
Identifiability analyse_identifiability(const PreisachGrid& grid, const std::vector<double>& u,
                                        const std::vector<int>& history = {0});

}  // namespace valvediag
