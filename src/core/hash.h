// SPDX-License-Identifier: MIT
#pragma once
// Content hashes for cache keys (pipeline/): a 64-bit, seedless, platform-fixed hash of bytes and
// of the values a stage reads. Not cryptographic: it detects changed inputs and damaged cache
// files, not an adversary (a cache directory is trusted as much as the scene file that names it).
//
// Hasher: streams values in order; add(x) for arithmetic types hashes their object bytes
// (little-endian x86-64 / aarch64 layout: keys are only compared on one kind of machine), strings
// with their length first so that ("ab","c") ≠ ("a","bc"). The mix is a multiply–xorshift
// (wyhash-style folding of 8-byte words) — about 4 GB/s per core, so hashing a 256 MB CT costs
// ~35 ms on 2 cores, far less than reading it.
//
// contentHash(volume): geometry, voxel type, value mapping, modality and every voxel byte. The
// voxel bytes are hashed in fixed 1 MiB chunks in parallel and the chunk hashes combined in order,
// so the result does not depend on the thread count.
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>

namespace voxlight::core {

class Volume;

/// 64-bit hash of a byte range (seeded; the same bytes and seed give the same value everywhere).
std::uint64_t hashBytes(const void* data, std::size_t size, std::uint64_t seed = 0);

/// 16 lower-case hex digits.
std::string hexKey(std::uint64_t key);

class Hasher {
  public:
    explicit Hasher(std::uint64_t seed = 0x9e3779b97f4a7c15ull) : h_(seed) {}
    Hasher& bytes(const void* data, std::size_t size) {
        mix(hashBytes(data, size, size));
        return *this;
    }
    Hasher& add(std::string_view s) { return bytes(s.data(), s.size()); }
    Hasher& add(const char* s) { return add(std::string_view(s)); }
    Hasher& add(const std::string& s) { return add(std::string_view(s)); }
    template <class T>
    requires std::is_arithmetic_v<T> || std::is_enum_v<T> Hasher& add(T v) {
        std::uint64_t w = 0;
        static_assert(sizeof(T) <= 8);
        std::memcpy(&w, &v, sizeof(T));
        mix(w ^ (std::uint64_t(sizeof(T)) << 56));
        return *this;
    }
    /// Several arithmetic values of a POD-like vector type (glm vectors, matrices).
    template <class V>
    Hasher& addPod(const V& v) {
        static_assert(std::is_trivially_copyable_v<V>);
        return bytes(&v, sizeof(V));
    }
    std::uint64_t value() const;

  private:
    void mix(std::uint64_t w);
    std::uint64_t h_;
    std::uint64_t n_ = 0;
};

/// Hash of everything that makes a volume render the way it does (see header comment).
std::uint64_t contentHash(const Volume& volume);

}  // namespace voxlight::core
