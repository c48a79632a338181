// SPDX-License-Identifier: MIT
// NRRD with attached data, .nrrd.
#include "fuzz_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    voxlight::fuzz::loadSingleFile(data, size, "in.nrrd");
    return 0;
}
