// SPDX-License-Identifier: MIT
#include "render/tonemap.h"

#include <algorithm>
#include <cmath>
#include <vector>

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

namespace {

/// Linear (exposed) value → display value in [0, 1].
float displayValue(float x, Display display) {
    switch (display) {
        case Display::Clinical:
            return x > 0.f ? std::min(x, 1.f) : 0.f;  // also NaN → 0
        case Display::Filmic:
            return linearToSrgb(acesFilmic(x));
        case Display::Srgb:
            break;
    }
    return linearToSrgb(x);
}

/// A display value that an 8-bit image stores as its top level.
constexpr float kDisplayWhite = 254.5f / 255.f;

/// The least linear value a display shows as white (bisection: every transform is monotone).
float whiteLinear(Display display) {
    float lo = 0.f, hi = 64.f;
    for (int i = 0; i < 40; ++i) {
        const float mid = 0.5f * (lo + hi);
        (displayValue(mid, display) >= kDisplayWhite ? hi : lo) = mid;
    }
    return hi;
}

}  // namespace

DisplayClipping displayClipping(const core::ImageRGBA& linear, float exposureStops, Display display,
                                float minAlpha) {
    DisplayClipping out;
    out.exposureToFit = exposureStops;
    const float k = std::exp2(exposureStops), white = whiteLinear(display);
    std::vector<float> largest;
    for (std::size_t i = 0; i < linear.pixels.size(); i += 4) {
        if (!(linear.pixels[i + 3] >= minAlpha)) continue;
        ++out.shown;
        float lo = INFINITY, hi = 0.f;
        for (int c = 0; c < 3; ++c) {
            const float x = std::isfinite(linear.pixels[i + c]) ? k * linear.pixels[i + c] : 0.f;
            lo = std::min(lo, x), hi = std::max(hi, x);
        }
        if (lo >= white) ++out.white;
        largest.push_back(hi);
    }
    if (largest.empty()) return out;
    const auto p95 = largest.begin() + std::ptrdiff_t(0.95 * double(largest.size() - 1));
    std::nth_element(largest.begin(), p95, largest.end());
    if (*p95 > 0.f)
        out.exposureToFit = std::floor(10.f * (exposureStops + std::log2(white / *p95))) / 10.f;
    return out;
}

core::ImageRGBA toDisplay(const core::ImageRGBA& linear, float exposureStops, Display display) {
    core::ImageRGBA out(linear.width, linear.height);
    const float k = std::exp2(exposureStops);
    auto map = [display](float x) { return displayValue(x, display); };
    for (std::size_t i = 0; i < linear.pixels.size(); i += 4) {
        for (int c = 0; c < 3; ++c) out.pixels[i + c] = map(k * linear.pixels[i + c]);
        out.pixels[i + 3] = 1.f;
    }
    return out;
}

}  // namespace voxlight::render
