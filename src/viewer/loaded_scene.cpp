// SPDX-License-Identifier: MIT
#include "viewer/loaded_scene.h"

#include "optics/presets.h"
#include "pipeline/pipeline.h"
#include "pipeline/scene_inputs.h"
#include "viewer/view_state.h"

namespace voxlight::viewer {

LoadedScene prepareScene(const io::Scene& input, const core::Progress& progress) {
    LoadedScene l;
    // The method and its params, the effects and the preset name: refused before any loading.
    (void)pipeline::Session().plan(input);
    pipeline::checkPresetName(input);
    auto volume = std::make_shared<core::Volume>(pipeline::loadSceneVolume(input, progress));
    l.document = io::sceneDocument(input);
    // No TF in the scene: the modality's default preset, named (as the pipeline chooses it).
    nlohmann::json& tf = l.document["transfer_function"];
    if (!tf.contains("preset") && !tf.contains("points"))
        tf["preset"] = optics::defaultPresetName(*volume);
    l.scene = sceneFromDocument(l.document, input.source);
    l.volume = volume;
    l.summary = summarize(*volume);
    l.histogram = histogram(*volume, l.summary.range, kHistogramBins, progress);
    l.robustRange = optics::robustRange(*volume);
    l.tf = pipeline::buildTransferFunction(l.scene, *volume);
    const auto bounds = volume->geometry().worldBounds();
    l.centre = 0.5 * (bounds[0] + bounds[1]);
    return l;
}

}  // namespace voxlight::viewer
