// SPDX-License-Identifier: MIT
#pragma once
// Film → display. The film holds linear radiance (EXR output keeps it). For 8-bit images one of
// three display transforms, after scaling by 2^exposure (non-finite values become 0):
//   Clinical  the composited value straight to the display, clamped to [0, 1] — how VTK and
//             3D Slicer show TF colours (their colours are display values, not radiance), so
//             voxlight's images read like the ones clinicians compare them to. Equal radiance
//             maps to equal grey everywhere. A MIP's/MinIP's grey (the window's ramp) is such a
//             display value too: the default shows the window as every PACS does (under srgb and
//             filmic it is encoded as any colour: the window's centre at 73.5 % grey in srgb).
//   Srgb      clamp, then the sRGB transfer curve (IEC 61966-2-1): physically right for a linear
//             film on an sRGB monitor, but flat and washed out next to VTK for TF-coloured DVR.
//   Filmic    the ACES filmic curve (Narkowicz's fit of the RRT+ODT), then sRGB: highlights roll
//             off (white is reached three stops above 1) instead of clipping at 1 — for the path tracer and the SH methods, whose radiance
//             under bright or several lights exceeds 1.
#include <string>

#include "core/image.h"

namespace voxlight::render {

enum class Display { Clinical, Srgb, Filmic };
/// "clinical" | "srgb" | "filmic"; throws InputError (source "image", field "display") otherwise.
Display displayFromString(const std::string& name);

float linearToSrgb(float linear);
float srgbToLinear(float encoded);
/// The ACES filmic curve (Narkowicz 2015), [0, ∞) → [0, 1], monotone, 0 at 0, 1 from about 7.9.
float acesFilmic(float linear);

/// Display-encoded copy (0..1) of a linear film, opaque (alpha 1): the film's RGB already holds
/// the background seen through the volume, and 8-bit writers would otherwise un-premultiply.
core::ImageRGBA toDisplay(const core::ImageRGBA& linear, float exposureStops = 0.f,
                          Display display = Display::Srgb);

/// How much of what an image shows its display turns white. A display channel counts as white
/// when it rounds to the top 8-bit level (≥ 254.5/255).
struct DisplayClipping {
    std::size_t shown = 0;  ///< pixels whose coverage (alpha) is at least `minAlpha`
    std::size_t white = 0;  ///< of them, those with all three channels white
    /// The exposure (stops) at which the 95th percentile of the shown pixels' largest channel just
    /// reaches white, rounded down to 0.1 stop (the exposure given when nothing shows).
    float exposureToFit = 0.f;
};
DisplayClipping displayClipping(const core::ImageRGBA& linear, float exposureStops, Display display,
                                float minAlpha);

}  // namespace voxlight::render
