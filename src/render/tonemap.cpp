// SPDX-License-Identifier: MIT
#include "render/tonemap.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace voxlight::render {

Display displayFromString(const std::string& name) {
    if (name == "clinical") return Display::Clinical;
    if (name == "srgb") return Display::Srgb;
    if (name == "filmic") return Display::Filmic;
    throw InputError("image", "display", "'" + name + "' is not a display transform",
                     "choose one of: clinical, srgb, filmic");
}

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

float acesFilmic(float x) {
    if (!(x > 0.f)) return 0.f;  // also NaN
    if (std::isinf(x)) return 1.f;
    // Narkowicz, "ACES Filmic Tone Mapping Curve" (2015): x(ax + b) / (x(cx + d) + e).
    constexpr float a = 2.51f, b = 0.03f, c = 2.43f, d = 0.59f, e = 0.14f;
    return std::clamp((x * (a * x + b)) / (x * (c * x + d) + e), 0.f, 1.f);
}

core::ImageRGBA toDisplay(const core::ImageRGBA& linear, float exposureStops, Display display) {
    core::ImageRGBA out(linear.width, linear.height);
    const float k = std::exp2(exposureStops);
    auto map = [display](float x) {
        switch (display) {
            case Display::Clinical:
                return x > 0.f ? std::min(x, 1.f) : 0.f;  // also NaN → 0
            case Display::Filmic:
                return linearToSrgb(acesFilmic(x));
            case Display::Srgb:
                break;
        }
        return linearToSrgb(x);
    };
    for (std::size_t i = 0; i < linear.pixels.size(); i += 4) {
        for (int c = 0; c < 3; ++c) out.pixels[i + c] = map(k * linear.pixels[i + c]);
        out.pixels[i + 3] = 1.f;
    }
    return out;
}

}  // namespace voxlight::render
