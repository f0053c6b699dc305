#pragma once
// Four doubles in vector registers (GCC's vector extension), and whether this processor runs
// AVX. A kernel templated on the four-lane type V is compiled twice: with V = Quad inside a
// function marked VALVEDIAG_AVX (one 256-bit instruction per operation) and with V = Pairs
// elsewhere (two SSE2 ones; GCC lowers a 256-bit vector without AVX through memory). Each lane
// does the same IEEE operations either way, so both give the same bits. Only AVX, never FMA: a
// fused multiply-add rounds once and would change them.

#include <cstdlib>
#include <cstring>

namespace valvediag {

using Pair = double __attribute__((vector_size(16)));
using Quad = double __attribute__((vector_size(32)));

#define VALVEDIAG_AVX __attribute__((target("avx")))

// Quad's lanes as two SSE2 pairs, with its operations lane by lane.
struct Pairs {
  Pair lo{}, hi{};
  friend Pairs operator+(Pairs a, Pairs b) { return {a.lo + b.lo, a.hi + b.hi}; }
  friend Pairs operator-(Pairs a, Pairs b) { return {a.lo - b.lo, a.hi - b.hi}; }
  friend Pairs operator*(Pairs a, Pairs b) { return {a.lo * b.lo, a.hi * b.hi}; }
  friend Pairs operator*(Pairs a, double s) { return {a.lo * s, a.hi * s}; }
  friend Pairs operator*(double s, Pairs a) { return {s * a.lo, s * a.hi}; }
  friend Pairs operator-(Pairs a, double s) { return {a.lo - s, a.hi - s}; }
  Pairs& operator+=(Pairs b) { return *this = *this + b; }
  Pairs& operator-=(Pairs b) { return *this = *this - b; }
  double operator[](int l) const { return l < 2 ? lo[l] : hi[l - 2]; }
};

// Lane access and loads that return no vector (a function returning a Quad without AVX enabled
// would change the ABI).
inline void set_lane(Quad& q, int l, double x) {
  q[l] = x;
}
inline void set_lane(Pairs& q, int l, double x) {
  if (l < 2)
    q.lo[l] = x;
  else
    q.hi[l - 2] = x;
}
inline void set4(Quad& q, double a, double b, double c, double d) {
  q = Quad{a, b, c, d};
}
inline void set4(Pairs& q, double a, double b, double c, double d) {
  q = {Pair{a, b}, Pair{c, d}};
}
inline void load(Quad& q, const double* p) {
  std::memcpy(&q, p, sizeof q);
}
inline void load(Pairs& q, const double* p) {
  std::memcpy(&q.lo, p, sizeof q.lo);
  std::memcpy(&q.hi, p + 2, sizeof q.hi);
}
inline void load(Pair& q, const double* p) {
  std::memcpy(&q, p, sizeof q);
}

// Whether the processor runs AVX (checked once, at start-up). VALVEDIAG_NO_AVX set in the
// environment takes the SSE2 code on any processor: the tests compare the two.
inline const bool kHaveAvx = [] {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx") != 0 && std::getenv("VALVEDIAG_NO_AVX") == nullptr;
}();

}  // namespace valvediag
