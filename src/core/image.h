// SPDX-License-Identifier: MIT
#pragma once
// A float RGBA image in memory: width × height pixels, 4 floats each (R, G, B, A interleaved), row
// 0 = top of the picture. The renderer's film holds linear radiance with coverage in alpha;
// environment maps hold linear radiance. A value type with no file format attached: reading and
// writing files is io/image.h (OpenImageIO), so libraries that only compute images need not link
// it.
#include <cstddef>
#include <vector>

namespace voxlight::core {

struct ImageRGBA {
    int width = 0, height = 0;
    std::vector<float> pixels;  ///< RGBA interleaved, row 0 = top; size = 4·width·height

    ImageRGBA() = default;
    ImageRGBA(int w, int h) : width(w), height(h), pixels(std::size_t(4) * w * h, 0.0f) {}
    float* at(int x, int y) { return pixels.data() + 4 * (std::size_t(y) * width + x); }
    const float* at(int x, int y) const { return pixels.data() + 4 * (std::size_t(y) * width + x); }
};

}  // namespace voxlight::core
