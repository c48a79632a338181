// SPDX-License-Identifier: MIT
#include "app/render_output.h"

#include "io/image.h"
#include "render/tonemap.h"

namespace voxlight::app {

const core::ImageRGBA& shownImage(const pipeline::RunResult& run) {
    const auto denoised = run.images.find("denoised");
    return denoised != run.images.end() ? denoised->second : run.image;
}

void writeDisplayImage(const pipeline::RunResult& run, const io::Scene& scene,
                       const std::filesystem::path& path) {
    io::writeImage(render::toDisplay(shownImage(run), float(scene.image.exposureStops),
                                     render::displayFromString(scene.image.display)),
                   path);
}

std::function<void(const pipeline::StageRecord&)> preloadImagesAfterInputs(
    std::optional<io::ImageModulePreload>& preload) {
    return [&preload](const pipeline::StageRecord& stage) {
        if (!preload && stage.kind != pipeline::StageKind::Input) preload.emplace();
    };
}

}  // namespace voxlight::app
