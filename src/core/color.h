// SPDX-License-Identifier: MIT
#pragma once
// Luminance of linear RGB: the Rec. 709 weights (ITU-R BT.709, the Y row of the linear sRGB →
// CIE XYZ matrix), the one definition behind every place that weighs colour channels by
// brightness (environment maps' importance and dominant direction, the path tracer's error
// estimate and denoiser, BRDF lobe choice, image metrics).
#include <glm/vec3.hpp>

namespace voxlight::core {

inline constexpr double kLuminanceWeights[3] = {0.2126, 0.7152, 0.0722};
inline constexpr float kLuminanceWeightsF[3] = {
    float(kLuminanceWeights[0]), float(kLuminanceWeights[1]), float(kLuminanceWeights[2])};

/// Y of a linear RGB colour, in double.
constexpr double luminance(double r, double g, double b) {
    return kLuminanceWeights[0] * r + kLuminanceWeights[1] * g + kLuminanceWeights[2] * b;
}
inline double luminance(const glm::dvec3& c) { return luminance(c.x, c.y, c.z); }
inline double luminance(const glm::vec3& c) { return luminance(c.r, c.g, c.b); }

}  // namespace voxlight::core
