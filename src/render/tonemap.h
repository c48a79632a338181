// SPDX-License-Identifier: MIT
#pragma once
// Film → display. Linear radiance is scaled by 2^exposure, clamped to [0, 1] (a clinical image
// should map equal radiance to equal grey everywhere, so no local or filmic operator) and encoded
// with the sRGB transfer curve (IEC 61966-2-1). Non-finite values become 0.
#include "core/image.h"

namespace voxlight::render {

float linearToSrgb(float linear);
float srgbToLinear(float encoded);

/// Display-encoded copy (sRGB, 0..1) of a linear film, opaque (alpha 1): the film's RGB already
/// holds the background seen through the volume, and 8-bit writers would otherwise un-premultiply.
core::ImageRGBA toDisplay(const core::ImageRGBA& linear, float exposureStops = 0.f);

}  // namespace voxlight::render
