// SPDX-License-Identifier: MIT
// Raw volume with an explicit layout (voxlight info FILE --dims --type --spacing ...). The first 40
// bytes are the layout as the command line would give it, the rest is the file:
//   0..11 dims (3 x int32 LE), 12 type (mod 4: uint8, int16, uint16, float32), 13 bit 0 big
//   endian, 14..15 header bytes (uint16 LE), 16..39 spacing (3 x float64 LE).
#include <cstring>

#include "fuzz_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace voxlight;
    constexpr std::size_t kLayoutBytes = 40;
    if (size < kLayoutBytes) return 0;
    io::RawLayout layout;
    std::int32_t dims[3];
    std::memcpy(dims, data, sizeof dims);
    layout.dims = {dims[0], dims[1], dims[2]};
    layout.type = core::VoxelType(data[12] % 4);
    layout.bigEndian = (data[13] & 1) != 0;
    layout.headerBytes = std::uint64_t(data[14]) | std::uint64_t(data[15]) << 8;
    double spacing[3];
    std::memcpy(spacing, data + 16, sizeof spacing);
    layout.spacing = {spacing[0], spacing[1], spacing[2]};
    io::ReadOptions options;
    options.raw = layout;
    fuzz::loadLikeInfo(fuzz::writeParts(data + kLayoutBytes, size - kLayoutBytes, {"in.raw"}),
                       options);
    return 0;
}
