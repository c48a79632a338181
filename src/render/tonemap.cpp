// SPDX-License-Identifier: MIT
#include "render/tonemap.h"

#include <algorithm>
#include <cmath>

namespace voxlight::render {

float linearToSrgb(float x) {
    if (!(x > 0.f)) return 0.f;  // also NaN
    if (x >= 1.f) return 1.f;
    return x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x, 1.f / 2.4f) - 0.055f;
}

float srgbToLinear(float e) {
    if (!(e > 0.f)) return 0.f;
    if (e >= 1.f) return 1.f;
    return e <= 0.04045f ? e / 12.92f : std::pow((e + 0.055f) / 1.055f, 2.4f);
}

core::ImageRGBA toDisplay(const core::ImageRGBA& linear, float exposureStops) {
    core::ImageRGBA out(linear.width, linear.height);
    const float k = std::exp2(exposureStops);
    for (std::size_t i = 0; i < linear.pixels.size(); i += 4) {
        for (int c = 0; c < 3; ++c) out.pixels[i + c] = linearToSrgb(k * linear.pixels[i + c]);
        out.pixels[i + 3] = 1.f;
    }
    return out;
}

}  // namespace voxlight::render
