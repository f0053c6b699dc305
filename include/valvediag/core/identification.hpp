// Identification of the Preisach-Hammerstein model (paper section 4, method notes).
//
// For a fixed b the equation error is linear in (a, c, mu) jointly: one nonnegative least-squares
// problem with a and c free. Only b's direction (nb - 1 dimensions) is searched, by alternating
// an (a, b, c) least-squares step with the joint solve until the cost stops falling. The paper's
// alternation (eqs 17-19) is kept as an option. The L1 budget (eq 17) is chosen by BIC over
// kappa in [0.95, 1] (eqs 21-22) on the exact homotopy path. Configurations (na, nb, nk, L) are
// scored by the simulated-output fitness (eq 20); unstable fitted models are rejected.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "valvediag/core/cancel.hpp"
#include "valvediag/core/hammerstein.hpp"
#include "valvediag/core/identifiability.hpp"
#include "valvediag/core/nnls.hpp"

namespace valvediag {

enum class FitMethod { Joint, Alternation };
enum class StopRule { CostDecrease, ParameterChange };
// Paper: s = sign of the first nonzero b multiplies mu (can flip mu negative and collapse it).
// KeepMuNonnegative: normalize by ||b|| only, the gain sign stays in b.
enum class Normalization { KeepMuNonnegative, PaperSign };
enum class InitialMemory { RisingFromMin, Estimate };

struct FitOptions {
  int na_min = 1, na_max = 3;
  int nb_min = 1, nb_max = 3;
  int nk_min = 0, nk_max = 10;
  int L_min = 2, L_max = 20;
  LinearBlock block = LinearBlock::Arx;
  FitMethod method = FitMethod::Joint;
  StopRule stop_rule = StopRule::CostDecrease;
  Normalization normalization = Normalization::KeepMuNonnegative;
  InitialMemory initial_memory = InitialMemory::Estimate;
  bool merge_identical_relays = true;
  double stop_tolerance = -1;  // <0: 1e-9 relative cost decrease, or 0.01 for ParameterChange
  int max_iterations = 200;    // inner iterations (b search or alternation)
  std::vector<double> kappas{1.0, 0.99, 0.98, 0.97, 0.96, 0.95};
  // BIC's sigma^2 (eq 22) from the simulated output as the paper says (one simulation per kappa,
  // O(N) each), or from the equation error, which the Gram matrix gives at no cost in N.
  bool bic_on_simulated_output = false;
  double validation_fraction = 0.0;  // last fraction of samples held out (0: none)
  std::size_t validation_start = 0;  // or: first held-out sample index (0: use the fraction)
  std::size_t first_sample = 0;      // first estimation sample (0: the largest lag)
  bool select_on_validation = false;
  double umin = 0.0, umax = 0.0;  // Preisach input range; both 0: the OP range of the data
  // Parsimony: among configurations within this many fitness points of the best, the one with the
  // fewest linear parameters (na + nb), then the coarsest L, then the smallest nk wins. Fitness
  // alone always prefers a bigger equivalent model by a hair (pole-zero near-cancellations).
  double parsimony_percent = 0.1;
  int threads = 0;  // 0: all cores
  bool keep_all_configurations = true;
  // Set by another thread: identify() throws Cancelled (cancel.hpp) at its next structure.
  const std::atomic<bool>* cancel = nullptr;
  // Called as the configurations are fitted (one call at a time, from identify()'s threads):
  // the share of the work done, rising to 1 (each L weighted by its number of relays).
  std::function<void(double)> progress;
};

// Checks the options alone; returns an empty string when they are usable, otherwise what is wrong.
std::string validate(const FitOptions& opt);

struct ConfigurationResult {
  Structure structure;
  double fitness_percent = 0.0;  // estimation data, simulated output (eq 20); NaN if unstable
  double validation_fitness_percent = 0.0;
  double bic = 0.0;
  double kappa = 1.0;
  double cost = 0.0;  // equation-error sum of squares
  int nonzero_weights = 0;
  int iterations = 0;
  bool stable = true;
  SolverStatus status = SolverStatus::Converged;
  std::string stop_reason;
};

enum class IdentificationStatus { Ok, NoStableModel };

struct IdentificationResult {
  IdentificationStatus status = IdentificationStatus::Ok;
  HammersteinModel model;
  ConfigurationResult best;
  std::vector<ConfigurationResult> configurations;
  double fitness_percent = 0.0;
  double validation_fitness_percent = 0.0;  // NaN without a split
  std::size_t first_sample = 0;             // t0: samples before seed the simulation
  std::size_t estimation_end = 0;           // one past the last estimation sample
  Identifiability identifiability;
  double initial_memory_gain_percent = 0.0;  // fitness gained by estimating the initial memory
  double elapsed_s = 0.0;
  int total_iterations = 0;
};

// u: controller output, y: process variable (or measured valve position with the identity block).
// Throws std::invalid_argument for an impossible problem (too few samples, constant input).
IdentificationResult identify(const std::vector<double>& u, const std::vector<double>& y,
                              const FitOptions& opt);

// Fits one configuration with the options' method (exposed for tests and the benchmark).
ConfigurationResult fit_configuration(const std::vector<double>& u, const std::vector<double>& y,
                                      const Structure& s, const FitOptions& opt,
                                      HammersteinModel* model_out = nullptr);

// Minimum number of samples for the options' largest model.
std::size_t minimum_samples(const FitOptions& opt);

}  // namespace valvediag
