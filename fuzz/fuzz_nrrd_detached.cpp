// SPDX-License-Identifier: MIT
// NRRD detached header in.nhdr + data files in.raw, in.raw.gz (parts split at VXLFUZZSPLIT).
#include "fuzz_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace voxlight::fuzz;
    loadLikeInfo(writeParts(data, size, {"in.nhdr", "in.raw", "in.raw.gz"}));
    return 0;
}
