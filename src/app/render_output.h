// SPDX-License-Identifier: MIT
#pragma once
// What `render` and `replay` both do with a pipeline run: the display image of a frame.
#include <filesystem>
#include <functional>
#include <optional>

#include "core/image.h"
#include "io/image.h"
#include "io/scene.h"
#include "pipeline/pipeline.h"

namespace voxlight::app {

/// The image the display file shows: pathtrace's denoised one when it made one, otherwise the
/// run's linear radiance (the EXR stays the raw estimate either way).
const core::ImageRGBA& shownImage(const pipeline::RunResult& run);

/// Writes shownImage(run) through the scene's display transform and exposure (image.display,
/// image.exposure) to `path` (format by extension: io::writeImage).
void writeDisplayImage(const pipeline::RunResult& run, const io::Scene& scene,
                       const std::filesystem::path& path);

/// A pipeline::RunOptions::afterStage hook (render, replay, sweep) that starts loading OpenImageIO
/// into `preload` once the first stage after the inputs is done: beside the stages, not beside
/// the volume read, whose reading child would wait for the load before forking (io/image.h).
std::function<void(const pipeline::StageRecord&)> preloadImagesAfterInputs(
    std::optional<io::ImageModulePreload>& preload);

}  // namespace voxlight::app
