// Deterministic pseudo-random numbers that give the same sequence on every platform and
// standard library (std::normal_distribution and friends are implementation-defined, so
// "same seed, same bytes" needs our own distributions).
#pragma once

#include <cmath>
#include <cstdint>

namespace segmatch {

// SplitMix64: used to expand one seed into independent streams (seed, stream id) -> state.
inline uint64_t splitmix64(uint64_t& state) {
  uint64_t z = (state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Hash several integers into one seed, e.g. mix_seed(world_seed, sequence, frame).
inline uint64_t mix_seed(uint64_t a, uint64_t b = 0, uint64_t c = 0) {
  uint64_t s = a;
  uint64_t h = splitmix64(s);
  s = h ^ b;
  h = splitmix64(s);
  s = h ^ c;
  return splitmix64(s);
}

// xoshiro256** 1.0 (Blackman & Vigna): small, fast, good statistical quality.
class Rng {
 public:
  explicit Rng(uint64_t seed = 1) {
    uint64_t s = seed;
    for (auto& word : state_) word = splitmix64(s);
  }

  uint64_t next_u64() {
    const uint64_t result = rotl(state_[1] * 5, 7) * 9;
    const uint64_t t = state_[1] << 17;
    state_[2] ^= state_[0];
    state_[3] ^= state_[1];
    state_[1] ^= state_[2];
    state_[0] ^= state_[3];
    state_[2] ^= t;
    state_[3] = rotl(state_[3], 45);
    return result;
  }

  // Uniform in [0, 1) with 53 bits of precision.
  double uniform() { return static_cast<double>(next_u64() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // Uniform integer in [0, n) (n > 0); the modulo bias is negligible for n << 2^64.
  uint64_t index(uint64_t n) { return next_u64() % n; }
  int uniform_int(int lo, int hi_inclusive) {
    return lo + static_cast<int>(index(static_cast<uint64_t>(hi_inclusive - lo + 1)));
  }
  bool bernoulli(double p) { return uniform() < p; }

  // Standard normal by Box-Muller (one value per call; simple and reproducible).
  double normal(double mean = 0.0, double sigma = 1.0) {
    double u1 = uniform();
    if (u1 < 1e-300) u1 = 1e-300;
    const double u2 = uniform();
    return mean + sigma * std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }

 private:
  static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  uint64_t state_[4];
};

}  // namespace segmatch
