// SPDX-License-Identifier: MIT
// MetaImage with LOCAL data, .mha.
#include "fuzz_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    voxlight::fuzz::loadSingleFile(data, size, "in.mha");
    return 0;
}
