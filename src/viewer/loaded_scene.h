// SPDX-License-Identifier: MIT
#pragma once
// A scene made ready for the viewer: validated (the method's plan), its volume loaded, summarized
// and binned, its transfer function resolved for that volume (the TF editor's starting point).
#include <array>
#include <memory>
#include <nlohmann/json.hpp>

#include "core/progress.h"
#include "core/volume.h"
#include "io/scene.h"
#include "optics/transfer_function.h"
#include "viewer/volume_summary.h"

namespace voxlight::viewer {

/// Bins of the TF editor's histogram.
inline constexpr int kHistogramBins = 256;

struct LoadedScene {
    /// The scene as an absolute document (io::sceneDocument): every later edit starts from it.
    nlohmann::json document;
    io::Scene scene;  ///< parsed from `document`
    std::shared_ptr<const core::Volume> volume;
    VolumeSummary summary;
    Histogram histogram;
    std::array<float, 2> robustRange{0.f, 1.f};  ///< for relative presets (optics/presets.h)
    optics::TransferFunction tf;                 ///< the scene's TF for this volume
    glm::dvec3 centre{0.0};                      ///< world centre of the volume's box, mm
};

/// Loads and checks `scene` (InputError naming the file and field on bad input; CancelledError).
/// Runs on a worker thread for files opened from the UI, before the window for the command line.
LoadedScene prepareScene(const io::Scene& scene, const core::Progress& progress);

}  // namespace voxlight::viewer
