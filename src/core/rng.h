// SPDX-License-Identifier: MIT
#pragma once
// Counter-based random numbers: a value is a pure function of (key..., seed), so results never
// depend on thread count or scheduling. Hash: a 64-bit finaliser chain (SplitMix64 / Stafford
// "Mix13") over the packed counters.
#include <cstdint>

namespace voxlight::core {

constexpr std::uint64_t mix64(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

/// Hash of up to four counters and a seed.
constexpr std::uint64_t hashCounters(std::uint64_t a, std::uint64_t b = 0, std::uint64_t c = 0,
                                     std::uint64_t seed = 0) {
    std::uint64_t h = mix64(seed + 0x9e3779b97f4a7c15ULL);
    h = mix64(h ^ a);
    h = mix64(h ^ (b + 0x632be59bd9b4e019ULL));
    h = mix64(h ^ (c + 0x8cb92ba72f3d8dd7ULL));
    return h;
}

/// Uniform float in [0, 1) from the top 24 bits of a hash.
constexpr float toUnitFloat(std::uint64_t h) { return float(h >> 40) * (1.0f / 16777216.0f); }
/// Uniform double in [0, 1) from the top 53 bits of a hash.
constexpr double toUnitDouble(std::uint64_t h) {
    return double(h >> 11) * (1.0 / 9007199254740992.0);
}

/// A small stream generator seeded from counters, for loops that need many numbers per key (e.g.
/// per pixel).
class CounterRng {
  public:
    constexpr explicit CounterRng(std::uint64_t key, std::uint64_t seed = 0)
        : state_(hashCounters(key, 0, 0, seed)) {}
    constexpr std::uint64_t next() { return mix64(state_ += 0x9e3779b97f4a7c15ULL); }
    constexpr float uniform() { return toUnitFloat(next()); }
    constexpr double uniformDouble() { return toUnitDouble(next()); }

  private:
    std::uint64_t state_;
};

}  // namespace voxlight::core
