// SPDX-License-Identifier: MIT
// VTK XML image data, .vti (inline, appended raw or base64, compressed or not).
#include "fuzz_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    voxlight::fuzz::loadSingleFile(data, size, "in.vti");
    return 0;
}
