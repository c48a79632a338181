// SPDX-License-Identifier: MIT
// MetaImage header in.mhd + data files in.raw, in.zraw (parts split at VXLFUZZSPLIT).
#include "fuzz_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace voxlight::fuzz;
    loadLikeInfo(writeParts(data, size, {"in.mhd", "in.raw", "in.zraw"}));
    return 0;
}
