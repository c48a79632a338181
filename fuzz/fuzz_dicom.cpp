// SPDX-License-Identifier: MIT
// One DICOM file (in.dcm, alone in its folder), read as voxlight info FILE reads it.
#include "fuzz_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    voxlight::fuzz::loadSingleFile(data, size, "in.dcm");
    return 0;
}
