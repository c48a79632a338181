// SPDX-License-Identifier: MIT
#pragma once
// Named transfer-function presets, chosen so that the phantoms and the real volumes in
// ../shared/datasets look like what a radiologist expects (colours are linear-RGB albedos,
// extinctions in 1/mm, values in HU for the CT presets):
//   ct-bone         skeleton: ivory bone, soft tissue transparent                (L 500,  W 2000)
//   ct-angio        contrast vessels red, bone ivory, metal (stents, clips) silver (L 400,  W 1400)
//   ct-soft-tissue  skin/fat faint, muscle and organs red-pink, bone white         (L 40,   W 400)
//   ct-lung         lung parenchyma as a translucent pink cast, airways            (L −600, W 1500)
//   mr-t1-brain     T1 head/brain surface; *relative*: authored on [0, 1] = the volume's robust
//                   range (1st–99.5th percentile), because MR intensities have no absolute unit
//   generic         relative grey ramp for anything else (phantoms, unknown modality)
//   phantom-step    σt = 0.02/mm above 0.5, 0 below: the exact-optics sphere/slab phantoms
// Surface channels (path tracer hybrid/BRDF scattering only): specular F0 / roughness bone 0.04 /
// 0.7 (matte), contrast lumen 0.08 / 0.3 (glossier), metal 0.9 / 0.25, soft tissue 0.03 / 0.8,
// lung 0.02 / 0.9, MR T1 and generic 0.04 / 0.5; phantom-step keeps the defaults (0, 1). No preset
// carries a phase g: the method's phase_g applies.
#include <array>
#include <string>
#include <vector>

#include "core/volume.h"
#include "optics/transfer_function.h"

namespace voxlight::optics {

struct PresetInfo {
    std::string name;
    std::string description;
    bool relative = false;  ///< authored on [0,1] of the volume's robust range
};
const std::vector<PresetInfo>& presetCatalog();
/// The catalogue entry of `name`, or nullptr.
const PresetInfo* findPreset(const std::string& name);
/// The preset names, comma-separated (for error messages).
std::string presetList();

/// Value range holding all but the tails of a volume's (finite) values: {q(loFraction),
/// q(hiFraction)} estimated from a strided subsample of ≈ 1 M voxels (deterministic).
std::array<float, 2> robustRange(const core::Volume& volume, float loFraction = 0.01f,
                                 float hiFraction = 0.995f);

/// Builds a preset. Relative presets are mapped onto `robust` (see robustRange). Throws InputError
/// (source "presets", field "name") naming the presets on an unknown name; the layer that read
/// the name maps it to its own key.
TransferFunction makePreset(const std::string& name, const std::array<float, 2>& robust = {0, 1});

/// Darkest-percent values a CT in Hounsfield units shows (air at −1000, padding down to −3024).
inline constexpr float kHounsfieldAirMin = -3100.f, kHounsfieldAirMax = -500.f;

/// True for a volume in Hounsfield units: a CT that says so, or one of unknown modality (NIfTI
/// carries none) whose darkest percent is air or padding and whose top is tissue/bone (≤ 4000).
bool looksLikeHounsfield(const core::Volume& volume);

/// The preset used when a scene names none: ct-bone for CT in HU (said, or recognised by
/// looksLikeHounsfield), mr-t1-brain for MR, generic otherwise.
std::string defaultPresetName(const core::Volume& volume);

}  // namespace voxlight::optics
