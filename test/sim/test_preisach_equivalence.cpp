// Proposition 1 of the paper: He's stiction model is a Preisach model. The He block of the
// simulator and PreisachModel with he_stiction_weights() (include/valvediag/core/preisach.hpp) must
// agree up to the discretization of the Preisach plane.
#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include "input_path.hpp"
#include "valvediag/core/preisach.hpp"
#include "valvediag/sim/valve_effects.hpp"

using namespace valvediag;

namespace {

using valvediag::test::path;

struct Mismatch {
  double max = 0.0, mean = 0.0, fraction = 0.0;  // fraction of samples off by more than 0.5
};

Mismatch compare(const PreisachGrid& grid, const std::vector<double>& u, double fs, double fd) {
  const PreisachWeights w = he_stiction_weights(grid, fs, fd);
  PreisachModel preisach(grid, w.mu, w.offset);
  const std::vector<double> xp = preisach.simulate(u);  // memory: input came up from umin
  HeStiction he(fs, fd);
  // Came down to umin: residual force -fd, x = umin + fd, like the weights' offset.
  he.reset(u.front(), u.front() + fd, -fd);
  Mismatch m;
  for (std::size_t k = 0; k < u.size(); ++k) {
    const double d = std::abs(he.step(u[k]) - xp[k]);
    m.max = std::max(m.max, d);
    m.mean += d;
    m.fraction += d > 0.5;
  }
  m.mean /= static_cast<double>(u.size());
  m.fraction /= static_cast<double>(u.size());
  return m;
}

}  // namespace

TEST_CASE("Proposition 1: He valve block equals PreisachModel with he_stiction_weights") {
  const double fs = 8.4, fd = 3.5243;  // the paper's Example 1 valve
  // Slow input from umin with nested reversals over the whole range, touching both ends.
  const auto u = path({0, 80, 30, 70, 45, 100, 20, 60, 0, 59, 41, 100, 41, 59}, 0.01);
  const Mismatch coarse = compare({0.0, 100.0, 16}, u, fs, fd);  // the paper's L
  const Mismatch medium = compare({0.0, 100.0, 100}, u, fs, fd);
  const Mismatch fine = compare({0.0, 100.0, 400}, u, fs, fd);
  // Where they differ it is by one slip (fs - fd), around a threshold the grid misplaces by up
  // to delta / 2 ...
  for (const auto& m : {coarse, medium, fine}) CHECK(m.max <= (fs - fd) + 0.1);
  // ... so the mismatch shrinks with the grid spacing delta = 100 / L.
  CHECK(coarse.mean > medium.mean);
  CHECK(medium.mean > fine.mean);
  CHECK(coarse.mean < (fs - fd) / 2);
  CHECK(fine.mean < 0.2);
  CHECK(fine.fraction < 0.03);
}
