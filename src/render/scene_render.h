// SPDX-License-Identifier: MIT
#pragma once
// Scene (io::Scene) → rendered film, stage by stage, with the stats of ARCHITECTURE.md §4. This is
// what `voxlight render` runs; the viewer and tests can run the same steps.
//
// Transfer function: a preset (optics/presets.h; relative presets are fitted to the volume's
// robust range) or explicit points; then `extinction_scale` multiplies σt, and `window`
// {level, width} remaps a preset's value axis onto the window. For explicit points the points are
// absolute and `window` only sets the MIP/MinIP grey ramp (default: the points' value range). No
// TF in the scene → the modality's default preset.
//
// Method params (all optional; unknown keys are an InputError naming the allowed ones):
//   every DVR method:     step (voxels; overrides render.step), preintegrated,
//   empty_space_skipping,
//                         early_termination, jitter (booleans)
//   emission-absorption:  ambient
//   gradient:             ambient, diffuse, specular, shininess, central_differences (true: 6-tap
//                         gradients; false: 3-tap forward differences, faster)
//   iso:                  iso_value (physical; default where the TF reaches 1/10 of its max σt),
//                         ambient, diffuse
//   mip, minip:           (window from the TF)
// Camera: fitting (distance/ortho_height 0) and the default target use the bounds of what the TF
// makes visible (visibleWorldBounds), not the whole volume.
// Lights: directional and point (radiance = color × intensity); other types are an InputError for
// these methods.
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"
#include "io/image.h"
#include "io/scene.h"
#include "optics/transfer_function.h"
#include "render/camera.h"
#include "render/ray_caster.h"

namespace voxlight::render {

struct StageRecord {
    std::string name;
    bool ran = true;
    std::string reason;  ///< what it did, or why it was skipped
    double seconds = 0.0;
};

/// Methods this renderer implements (a subset of io::knownMethods()).
const std::vector<std::string>& rayCasterMethods();

/// Loads the scene's volume (phantom or file).
core::Volume loadSceneVolume(const io::Scene& scene, const core::Progress& progress);
/// The scene's TF for this volume (see header comment).
optics::TransferFunction buildTransferFunction(const io::Scene& scene, const core::Volume& volume);
CameraSpec buildCameraSpec(const io::CameraDesc& desc);
/// Render options from method, params, lights, clip planes, image and render settings. `used`
/// receives the method parameters as used (defaults filled in). Everything about the scene that
/// can be checked without its volume is checked here (method, params, TF preset name, ...):
/// throws InputError naming the field.
RenderOptions buildRenderOptions(const io::Scene& scene, nlohmann::json* used = nullptr);

/// Throws InputError (field transfer_function.preset) when the scene names a TF preset that does
/// not exist (part of buildRenderOptions; also for scenes of methods this renderer lacks).
void checkPresetName(const io::Scene& scene);

/// Most frames renderScene() repeats (a timing aid, not a batch renderer).
inline constexpr int kMaxFrames = 1000;

struct SceneRenderResult {
    core::ImageRGBA film;  ///< linear radiance, alpha = coverage
    std::vector<StageRecord> stages;
    nlohmann::json method;   ///< {"name", "params" as used}
    nlohmann::json details;  ///< TF, camera, volume, counters
    RenderStats stats;
};

/// Runs load → brick grid → TF → render. Throws InputError on bad scene content. With frames > 1
/// the frame is rendered that many times (same image each time): the "render" stage reports the
/// median frame, details.frame_seconds every frame (for timing a view as an interactive viewer
/// would redraw it, after the one-time preparation).
SceneRenderResult renderScene(const io::Scene& scene,
                              const core::Progress& progress = core::Progress::none(),
                              int frames = 1);

/// Stats JSON (ARCHITECTURE.md §4): stages, total_seconds, peak_rss_mb, method, details.
nlohmann::json statsJson(const SceneRenderResult& result, double totalSeconds);

}  // namespace voxlight::render
