// SPDX-License-Identifier: MIT
// NIfTI-1/2 (and Analyze-like) single file, .nii.
#include "fuzz_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    voxlight::fuzz::loadSingleFile(data, size, "in.nii");
    return 0;
}
