// SPDX-License-Identifier: MIT
// A DICOM series folder of up to four files s0.dcm..s3.dcm (parts split at VXLFUZZSPLIT),
// read as voxlight info FOLDER reads it.
#include "fuzz_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace voxlight::fuzz;
    (void)writeParts(data, size, {"s0.dcm", "s1.dcm", "s2.dcm", "s3.dcm"});
    loadLikeInfo(scratchDir());
    return 0;
}
