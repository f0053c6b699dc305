// The Hammerstein model: a discretized Preisach valve followed by an ARX process (method notes):
//   A(q^-1) y(t) = B(q^-1) x(t) + c + e(t),   x(t) = gamma(u(t))' mu,
//   B = b1 q^-(nk+1) + ... + b_nb q^-(nk+nb).
// With the identity linear block (valve position measured), y(t) = x(t) + c.
#pragma once

#include <complex>
#include <cstddef>
#include <optional>
#include <vector>

#include "valvediag/core/preisach.hpp"

namespace valvediag {

struct Structure {
  int na = 1, nb = 1, nk = 0, L = 10;
  bool operator==(const Structure&) const = default;
};

enum class LinearBlock { Arx, Identity };

struct HammersteinModel {
  Structure structure;
  LinearBlock block = LinearBlock::Arx;
  PreisachGrid grid;
  std::vector<double> mu;               // K weights, >= 0, paper order (eq 14)
  std::vector<int> initial_history{0};  // virtual-input levels before the first sample
  std::vector<double> a, b;             // A = 1 + a1 q^-1 + ...; ||b|| = 1, gain sign kept in b
  double c = 0.0;
};

// Valve position x(t) of the model for input u, starting from its initial memory.
std::vector<double> simulate_valve(const HammersteinModel& m, const std::vector<double>& u);

// Simulated output (eq 20): driven by u only; the first t0 samples are taken from y (they seed
// the recursion, as the measured past before the simulation starts).
std::vector<double> simulate_output(const HammersteinModel& m, const std::vector<double>& u,
                                    const std::vector<double>& y, std::size_t t0);
// The same from a precomputed valve position.
std::vector<double> simulate_arx(const HammersteinModel& m, const std::vector<double>& x,
                                 const std::vector<double>& y, std::size_t t0);

// Fitness (eq 20) on samples [from, to): (1 - ||ys - y|| / ||y - mean(y)||) * 100.
double fitness_percent(const std::vector<double>& y, const std::vector<double>& ys,
                       std::size_t from, std::size_t to);

// True when all roots of A(z) lie strictly inside the unit circle (margin on the radius).
bool is_stable(const std::vector<double>& a, double margin = 1e-9);
// Roots of A(z) (the poles; empty for na = 0), nullopt when the eigen-solve fails.
std::optional<std::vector<std::complex<double>>> poles_of(const std::vector<double>& a);
// Largest root modulus of A(z) (0 for na = 0).
double spectral_radius(const std::vector<double>& a);

}  // namespace valvediag
