#include <doctest/doctest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include "input_path.hpp"
#include "valvediag/sim/valve_effects.hpp"

using namespace valvediag;

namespace {

using valvediag::test::path;

template <class Block>
std::vector<double> run(Block& b, const std::vector<double>& u) {
  std::vector<double> x;
  for (double v : u) x.push_back(b.step(v));
  return x;
}

void check_sequence(const std::vector<double>& got, const std::vector<double>& want) {
  REQUIRE(got.size() == want.size());
  for (std::size_t k = 0; k < got.size(); ++k) {
    CAPTURE(k);
    CHECK(got[k] == doctest::Approx(want[k]).epsilon(1e-12));
  }
}

}  // namespace

TEST_CASE("He stiction follows the Figure 5 flowchart on a hand-computed sequence") {
  HeStiction he(3.0, 1.0);
  he.reset(0.0);
  // u_cum builds 1, 2, 3 (not > fs), slips at 3.5 to x = u - fd, builds again, slips down at -1.
  const std::vector<double> u{1, 2, 3, 3.5, 4.5, 5, 4, 2, 0.5, -1, -1.5};
  check_sequence(run(he, u), {0, 0, 0, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5, 0, 0});
  CHECK(he.residual_force() == doctest::Approx(-1.5));
}

TEST_CASE("He stiction signature on a slow triangle: band fs, slip jump fs - fd") {
  const double fs = 8.4, fd = 3.5243, du = 0.01;
  HeStiction he(fs, fd);
  const auto u = path({20, 80, 20, 80}, du);
  he.reset(u[0]);
  double x_prev = he.output();
  int slips = 0;
  double last_reversal = 20.0;
  bool moved_since_reversal = true;
  int dir = +1;
  for (std::size_t k = 1; k < u.size(); ++k) {
    const int d = u[k] > u[k - 1] ? 1 : -1;
    if (d != dir) {
      dir = d;
      last_reversal = u[k - 1];
      moved_since_reversal = false;
    }
    const double x = he.step(u[k]);
    CAPTURE(k);
    CAPTURE(u[k]);
    if (x != x_prev) {
      ++slips;
      // Slip exactly when the input is more than fs away from the position ...
      CHECK(std::abs(u[k] - x_prev) > fs);
      CHECK(std::abs(u[k] - x_prev) <= fs + du + 1e-9);
      // ... the jump is fs - fd (up to one input step) ...
      CHECK(std::abs(std::abs(x - x_prev) - (fs - fd)) <= du + 1e-9);
      // ... in the direction of the input, and the valve ends fd behind the input.
      CHECK((x - x_prev) * dir > 0);
      CHECK(std::abs(u[k] - x) == doctest::Approx(fd));
      if (!moved_since_reversal && k > 1) {
        // After a reversal the input first undoes the residual force (fd .. fs) and then needs
        // fs the other way: it travels between fs + fd and 2 fs before the first slip.
        const double travel = std::abs(u[k] - last_reversal);
        CHECK(travel >= fs + fd - du);
        CHECK(travel <= 2 * fs + du);
      }
      moved_since_reversal = true;
    } else {
      CHECK(std::abs(u[k] - x) <= fs + 1e-9);  // sticking: inside the static band
    }
    x_prev = x;
  }
  // Three ramps of 60 %: about 60 / (fs - fd) slips each.
  CHECK(slips >= 3 * 10);
  CHECK(slips <= 3 * 13);
}

TEST_CASE("Kano and Choudhury stiction on hand-computed sequences") {
  // S = 4, J = 2: a moving valve follows x = u - d (S - J)/2 = u - d.
  const std::vector<double> u{1, 3, 4.5, 5, 6, 6, 6.5, 8.5, 10.5, 9, 7, 6, 5.5};
  SUBCASE("Kano: after a pause in the same direction only J is needed") {
    KanoStiction kano(4.0, 2.0);
    kano.reset(0.0);
    // 4.5: first move (> S from rest); 6,6: input pauses, valve stops at u_s = 6;
    // 8.5: 2.5 > J past u_s in the same direction: moves; 9: reversal, stops at u_s = 10.5;
    // 6: 4.5 > S back: moves down, x = u + 1.
    check_sequence(run(kano, u), {0, 0, 3.5, 4, 5, 5, 5, 7.5, 9.5, 9.5, 9.5, 7, 6.5});
  }
  SUBCASE("Choudhury: every velocity sign change re-sticks and needs S again") {
    ChoudhuryStiction ch(4.0, 2.0);
    ch.reset(0.0);
    // Same as Kano except at 8.5: the pause reset x_ss to 6 and 2.5 < S, so it stays stuck
    // until 10.5 (4.5 past x_ss).
    check_sequence(run(ch, u), {0, 0, 3.5, 4, 5, 5, 5, 5, 9.5, 9.5, 9.5, 7, 6.5});
  }
  SUBCASE("Choudhury: a jump larger than S moves the valve in the same sample") {
    ChoudhuryStiction ch(4.0, 2.0);
    ch.reset(10.0);
    CHECK(ch.step(20.0) == doctest::Approx(19.0));
    CHECK(ch.step(12.0) == doctest::Approx(13.0));
  }
}

TEST_CASE("Stenman stiction on a hand-computed sequence") {
  StenmanStiction st(2.0);
  st.reset(0.0);
  check_sequence(run(st, {1, 2, 2.5, 3, 1.5, 0.4, 0.6, -1}), {0, 0, 2.5, 2.5, 2.5, 0.4, 0.4, 0.4});
}

TEST_CASE("Position-dependent stiction") {
  SUBCASE("constant bands: identical to He's model") {
    PositionDependentStiction pd({{50.0, 8.4, 3.5243}});
    HeStiction he(8.4, 3.5243);
    std::mt19937_64 rng(3);
    std::normal_distribution<double> n(0.0, 1.0);
    double u = 50;
    pd.reset(u);
    he.reset(u);
    for (int k = 0; k < 5000; ++k) {
      u += n(rng);
      REQUIRE(pd.step(u) == he.step(u));
    }
  }
  SUBCASE("the band depends on where the valve is") {
    PositionDependentStiction pd({{20.0, 8.0, 3.0}, {40.0, 1.5, 0.5}});
    CHECK(pd.fs_at(10.0) == doctest::Approx(8.0));
    CHECK(pd.fs_at(30.0) == doctest::Approx(4.75));
    CHECK(pd.fd_at(30.0) == doctest::Approx(1.75));
    CHECK(pd.fs_at(90.0) == doctest::Approx(1.5));
    // Near closed: the ramp must go 8 before the valve moves, then it jumps by 5.
    pd.reset(10.0);
    const auto u = path({10, 30}, 0.01);
    double first_move = -1;
    for (double v : u) {
      if (pd.step(v) != 10.0) {
        first_move = v;
        break;
      }
    }
    CHECK(first_move == doctest::Approx(18.0).epsilon(0.001));
    CHECK(pd.output() == doctest::Approx(15.0).epsilon(0.001));
    // Wide open: it moves after 1.5.
    pd.reset(60.0);
    for (double v : path({60, 62}, 0.01)) {
      if (pd.step(v) != 60.0) {
        first_move = v;
        break;
      }
    }
    CHECK(first_move == doctest::Approx(61.5).epsilon(0.001));
  }
  SUBCASE("the motion at the start, as He's: the valve lags OP by the band where it starts") {
    PositionDependentStiction up({{20.0, 8.0, 3.0}, {40.0, 1.5, 0.5}}, 1.0);
    CHECK(up.initial_motion() == 1.0);
    up.reset(10.0);
    CHECK(up.output() == doctest::Approx(7.0));  // fd 3 below 20 %
    PositionDependentStiction down({{20.0, 8.0, 3.0}, {40.0, 1.5, 0.5}}, -1.0);
    down.reset(60.0);
    CHECK(down.output() == doctest::Approx(60.5));  // fd 0.5 above 40 %
    // Moving up already (residual force fd): it slips after fs - fd more, not 2 fs.
    up.reset(10.0);
    CHECK(up.step(14.9) == doctest::Approx(7.0));
    CHECK(up.step(15.1) == doctest::Approx(12.1));
    CHECK_THROWS_AS(PositionDependentStiction({{0.0, 1.0, 0.5}}, 1.5), std::invalid_argument);
  }
  CHECK_THROWS_AS(PositionDependentStiction({{40.0, 1.0, 0.5}, {20.0, 2.0, 1.0}}),
                  std::invalid_argument);
  CHECK_THROWS_AS(PositionDependentStiction({{40.0, 1.0, 2.0}}), std::invalid_argument);
}

TEST_CASE("Deadband: backlash loop of width d without jumps") {
  const double d = 4.0, du = 0.01;
  Deadband db(d);
  const auto u = path({50, 80, 30, 80}, du);
  db.reset(u[0]);
  double x_prev = db.output();
  double width_up = 0, width_down = 0;
  int reversal_checks = 0;
  for (std::size_t k = 1; k < u.size(); ++k) {
    const double x = db.step(u[k]);
    CHECK(std::abs(x - x_prev) <= std::abs(u[k] - u[k - 1]) + 1e-12);  // never a jump
    CHECK(std::abs(u[k] - x) <= d / 2 + 1e-12);
    if (x > x_prev) width_up = u[k] - x;
    if (x < x_prev) width_down = x - u[k];
    // Just after the reversal at 80 the valve stays until u has come back d.
    if (u[k] < 80 && u[k] > 76 + du && u[k - 1] > u[k] && k < u.size() / 2) {
      CHECK(x == doctest::Approx(78.0));
      ++reversal_checks;
    }
    x_prev = x;
  }
  CHECK(width_up + width_down == doctest::Approx(d));
  CHECK(reversal_checks > 300);
  // Pushed up to 82.5 the valve sits at 80.5 and holds until u falls below 80.5 - d/2.
  Deadband db2(d);
  db2.reset(80.0);  // rest position 80, play centred
  CHECK(db2.step(82.5) == doctest::Approx(80.5));
  CHECK(db2.step(79.0) == doctest::Approx(80.5));
  CHECK(db2.step(78.5) == doctest::Approx(80.5));
  CHECK(db2.step(76.0) == doctest::Approx(78.0));
}

TEST_CASE("Saturation clips to the travel limits") {
  Saturation s(5.0, 70.0);
  check_sequence(run(s, {-10, 5, 6, 69.9, 70, 95}), {5, 5, 6, 69.9, 70, 70});
  CHECK_THROWS_AS(Saturation(70.0, 70.0), std::invalid_argument);
}

TEST_CASE("Installed characteristics map 0..100 onto 0..100") {
  Characteristic eq(Characteristic::Kind::equal_percentage, 50.0);
  Characteristic qo(Characteristic::Kind::quick_opening, 50.0);
  Characteristic lin(Characteristic::Kind::linear, 0.0);
  CHECK(eq.step(0.0) == doctest::Approx(0.0));
  CHECK(eq.step(100.0) == doctest::Approx(100.0));
  CHECK(eq.step(50.0) == doctest::Approx(100.0 * (std::sqrt(50.0) - 1.0) / 49.0));  // 12.39
  CHECK(qo.step(0.0) == doctest::Approx(0.0));
  CHECK(qo.step(100.0) == doctest::Approx(100.0));
  CHECK(eq.step(120.0) == doctest::Approx(100.0));  // clamped to the travel
  double prev = -1;
  for (double u = 0; u <= 100; u += 0.5) {
    const double x = eq.step(u);
    CHECK(x > prev);                          // monotone
    CHECK(qo.step(x) == doctest::Approx(u));  // quick-opening is the inverse
    CHECK(lin.step(u) == doctest::Approx(u));
    CHECK(x <= u + 1e-12);  // equal-percentage lies below the diagonal
    prev = x;
  }
  CHECK_THROWS_AS(Characteristic(Characteristic::Kind::equal_percentage, 1.0),
                  std::invalid_argument);
  CHECK(characteristic_kind_from_string("quick-opening") == Characteristic::Kind::quick_opening);
  CHECK_THROWS_AS(characteristic_kind_from_string("butterfly"), std::invalid_argument);
}

TEST_CASE("Actuator lag: exact first-order step response, 63 % at tau") {
  const double tau = 10.0, Ts = 0.5;
  ActuatorLag lag(tau, Ts);
  lag.reset(0.0);
  for (int k = 0; k <= 100; ++k) {
    const double x = lag.step(1.0);
    CAPTURE(k);
    CHECK(x == doctest::Approx(1.0 - std::exp(-k * Ts / tau)).epsilon(1e-12));
    if (k == 20) CHECK(x == doctest::Approx(1.0 - std::exp(-1.0)).epsilon(1e-12));  // 63.2 %
  }
  ActuatorLag none(0.0, Ts);
  none.reset(3.0);
  CHECK(none.step(7.0) == 7.0);
}

TEST_CASE("Preisach valve wraps PreisachModel") {
  const PreisachGrid g{0.0, 100.0, 4};
  std::vector<double> mu(static_cast<std::size_t>(g.relay_count()));
  for (std::size_t k = 0; k < mu.size(); ++k) mu[k] = 1.0 + static_cast<double>(k);
  PreisachValve valve(g, mu, 2.0);
  PreisachModel model(g, mu, 2.0);
  const std::vector<double> u{0, 30, 80, 60, 20, 55, 100, 0};
  valve.reset(0.0);
  const auto want = model.simulate(u);
  check_sequence(run(valve, u), want);
  // Rest at 60 means the input came up from umin to 60.
  valve.reset(60.0);
  model.reset({0, g.level(60.0)});
  CHECK(valve.output() == doctest::Approx(model.step(60.0)));
}

TEST_CASE("Valve chain applies blocks in order and rests consistently") {
  ValveChain a({Deadband(4.0), Saturation(10.0, 60.0)});
  ValveChain b({Saturation(10.0, 60.0), Deadband(4.0)});
  CHECK(a.reset(50.0) == 50.0);
  CHECK(b.reset(50.0) == 50.0);
  // OP 70: the deadband lets 68 through and saturation clips it; the other order clips first.
  CHECK(a.step(70.0) == 60.0);
  CHECK(b.step(70.0) == 58.0);
  ValveChain eq({Characteristic(Characteristic::Kind::equal_percentage, 50.0)});
  CHECK(eq.reset(50.0) == doctest::Approx(100.0 * (std::sqrt(50.0) - 1.0) / 49.0));
  ValveChain linear;
  CHECK(linear.reset(42.0) == 42.0);
  CHECK(linear.step(43.5) == 43.5);
}

TEST_CASE("Effect names are the product names of effects.md") {
  CHECK(effect_name(HeStiction(2, 1)) == "stiction");
  CHECK(effect_model(HeStiction(2, 1)) == "he");
  CHECK(effect_model(KanoStiction(2, 1)) == "kano");
  CHECK(effect_model(ChoudhuryStiction(2, 1)) == "choudhury");
  CHECK(effect_model(StenmanStiction(2)) == "stenman");
  CHECK(effect_model(PositionDependentStiction({{0, 2, 1}})) == "position-dependent");
  CHECK(effect_name(Deadband(1)) == "deadband");
  CHECK(effect_name(Saturation(0, 1)) == "saturation");
  CHECK(effect_name(Characteristic(Characteristic::Kind::quick_opening, 20)) == "characteristic");
  CHECK(effect_name(ActuatorLag(1, 1)) == "actuator-lag");
  CHECK(effect_name(PreisachValve(PreisachGrid{0, 100, 2}, {0, 0, 0})) == "preisach");
  CHECK(describe(HeStiction(8.4, 3.5243)) == "stiction (he: fs=8.4, fd=3.5243)");
  CHECK(describe(Deadband(4)) == "deadband (d=4)");
}

TEST_CASE("Bad parameters are rejected") {
  CHECK_THROWS_AS(HeStiction(1.0, 2.0), std::invalid_argument);
  CHECK_THROWS_AS(HeStiction(1.0, -0.5), std::invalid_argument);
  CHECK_THROWS_AS(KanoStiction(1.0, 2.0), std::invalid_argument);
  CHECK_THROWS_AS(ChoudhuryStiction(-1.0, 0.0), std::invalid_argument);
  CHECK_THROWS_AS(StenmanStiction(-1.0), std::invalid_argument);
  CHECK_THROWS_AS(Deadband(std::nan("")), std::invalid_argument);
  CHECK_THROWS_AS(ActuatorLag(-1.0, 1.0), std::invalid_argument);
  CHECK_THROWS_AS(ActuatorLag(1.0, 0.0), std::invalid_argument);
}
