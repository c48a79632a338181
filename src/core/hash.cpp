// SPDX-License-Identifier: MIT
#include "core/hash.h"

#include <tbb/parallel_for.h>

#include <cstdio>
#include <vector>

#include "core/volume.h"

namespace voxlight::core {

namespace {
constexpr std::uint64_t kM1 = 0xa0761d6478bd642full, kM2 = 0xe7037ed1a0b428dbull,
                        kM3 = 0x8ebc6af09c88c6e3ull;

/// 64×64 → 128-bit multiply folded to 64 bits (wyhash's mum).
inline std::uint64_t mum(std::uint64_t a, std::uint64_t b) {
    const unsigned __int128 r = (unsigned __int128)a * b;
    return std::uint64_t(r) ^ std::uint64_t(r >> 64);
}

inline std::uint64_t load8(const unsigned char* p) {
    std::uint64_t w;
    std::memcpy(&w, p, 8);
    return w;
}

/// Voxel bytes are hashed in chunks of this size, in parallel, then combined in order.
constexpr std::size_t kChunkBytes = std::size_t(1) << 20;
}  // namespace

std::uint64_t hashBytes(const void* data, std::size_t size, std::uint64_t seed) {
    const auto* p = static_cast<const unsigned char*>(data);
    std::uint64_t a = seed ^ kM1, b = mum(seed ^ kM2, size ^ kM3);
    std::size_t i = 0;
    // Two independent lanes of 8-byte words (keeps two multipliers busy).
    for (; i + 16 <= size; i += 16) {
        a = mum(load8(p + i) ^ a ^ kM2, kM1 ^ (a << 1));
        b = mum(load8(p + i + 8) ^ b ^ kM3, kM1 ^ (b >> 1));
    }
    std::uint64_t tail = 0;
    if (size > i) std::memcpy(&tail, p + i, size - i < 8 ? size - i : 8);
    a ^= tail;
    if (size - i > 8) {
        std::uint64_t t2 = 0;
        std::memcpy(&t2, p + i + 8, size - i - 8);
        b ^= t2;
    }
    return mum(mum(a ^ kM1, b ^ kM2), size ^ kM3);
}

std::string hexKey(std::uint64_t key) {
    char buf[17];
    std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(key));
    return buf;
}

void Hasher::mix(std::uint64_t w) {
    ++n_;
    h_ = mum(h_ ^ w ^ kM1, kM2 ^ n_);
}

std::uint64_t Hasher::value() const { return mum(h_ ^ kM3, n_ ^ kM1); }

std::uint64_t contentHash(const Volume& volume) {
    const Geometry& g = volume.geometry();
    Hasher h;
    h.add("voxlight.volume.v1");
    h.addPod(g.dims).addPod(g.spacing).addPod(g.origin).addPod(g.direction);
    h.add(int(volume.type())).add(volume.mapping.slope).add(volume.mapping.intercept);
    h.add(volume.mapping.unit).add(int(volume.modality));
    const std::size_t bytes = std::size_t(volume.voxelCount()) * voxelBytes(volume.type());
    const std::size_t chunks = (bytes + kChunkBytes - 1) / kChunkBytes;
    std::vector<std::uint64_t> part(chunks);
    const auto* p = static_cast<const unsigned char*>(volume.data());
    tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t c) {
        const std::size_t off = c * kChunkBytes;
        part[c] = hashBytes(p + off, std::min(kChunkBytes, bytes - off), c);
    });
    h.add(std::uint64_t(bytes));
    if (!part.empty()) h.bytes(part.data(), part.size() * sizeof(std::uint64_t));
    return h.value();
}

}  // namespace voxlight::core
