// Where a model fails, and which physical effect the failure points to.
//
// Takes the controller output u, the measured output y and the model's simulated output y_sim on
// one window and returns (1) the time intervals where the residual stands out beyond its noise
// level, (2) the operating regions that carry the error (OP level, direction of travel, time since
// the last OP reversal), and (3) residual tests, each tied to the effects of
// ../shared/design/effects.md whose signature it detects. Pure computation: no printing, no files.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace valvediag {

struct ResidualInterval {
  std::size_t begin = 0, end = 0;  // samples [begin, end)
  double rms = 0.0;                // residual RMS inside
  double share = 0.0;              // share of the window's squared error inside, 0..1
};

struct ResidualRegion {
  std::string kind;           // "op-level", "direction", "since-reversal"
  std::string label;          // e.g. "OP 40-45 %", "rising", "0-10 samples after a reversal"
  double lo = 0.0, hi = 0.0;  // bounds in the kind's unit (OP %, samples); direction: -1, 0, +1
  std::size_t samples = 0;
  double rms = 0.0;     // residual RMS in the region
  double mean = 0.0;    // mean residual (bias) in the region
  double share = 0.0;   // share of the squared error, 0..1
  double excess = 0.0;  // share of the error / share of the samples (1: average)
};

// One residual test. `score` is 0 (no sign of the effect) .. 1 (strong sign), comparable across
// tests; `statistic` is the raw figure, described in `detail`.
struct ResidualTest {
  std::string name;                  // e.g. "reversal-locked"
  std::vector<std::string> effects;  // effect names it points to
  double statistic = 0.0;
  double score = 0.0;
  std::string detail;
};

struct ResidualAnalysisOptions {
  std::size_t model_delay = 0;      // nk + 1 of the fitted model: cross-correlation beyond this lag
  int op_bins = 8;                  // OP level bins
  double interval_threshold = 2.5;  // residual moving RMS above this many noise levels
  std::size_t smoothing = 0;        // moving-RMS window in samples (0: from the data, >= 10)
  int max_lag = 40;                 // cross-correlation and whiteness lags
  std::size_t max_intervals = 8;
};

struct ResidualAnalysis {
  double rms = 0.0;          // residual RMS over the window
  double noise_level = 0.0;  // robust estimate of the residual's white part (differenced MAD)
  std::vector<ResidualInterval> intervals;  // worst first
  std::vector<ResidualRegion> regions;      // all regions, by kind, in order
  std::vector<ResidualTest> tests;          // in a fixed order
  std::size_t reversals = 0;                // OP direction reversals in the window
  const ResidualTest* test(const std::string& name) const;
};

// Throws std::invalid_argument when the series differ in length or the window is too short (< 20).
ResidualAnalysis analyse_residual(const std::vector<double>& u, const std::vector<double>& y,
                                  const std::vector<double>& y_sim, std::size_t from,
                                  std::size_t to, const ResidualAnalysisOptions& opt = {});

// OP direction reversals, as sample indices, ignoring moves smaller than `hysteresis` (OP units).
std::vector<std::size_t> op_reversals(const std::vector<double>& u, std::size_t from,
                                      std::size_t to, double hysteresis);

}  // namespace valvediag
