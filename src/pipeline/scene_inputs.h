// SPDX-License-Identifier: MIT
#pragma once
// From the scene's descriptions (io::Scene) to the libraries' types, each in one place: the volume
// and its source identity, the transfer function, the camera spec, and the lights.
//
// Transfer function: a preset (optics/presets.h; relative presets are fitted to the volume's
// robust range) or explicit points; then `extinction_scale` multiplies σt, and `window`
// {level, width} remaps a preset's value axis onto the window. For explicit points the points are
// absolute and `window` only sets the MIP/MinIP grey ramp (default: the points' value range). No
// TF in the scene → the modality's default preset.
//
// Lights: the scene file gives a directional light's `direction` as the direction the light
// *travels* (as VTK and glTF do); below io every direction points *toward* the light
// (lights/light.h). buildLights() is the one place that converts. Radiometry: colour × intensity
// is a directional light's irradiance, a point light's intensity, an area light's emitted radiance
// and an environment map's scale (per channel). Area shapes: sphere (position, radius), disk
// (position, normal, radius), rect (centre `position`, `normal`, `size` [w, h]; its edges are an
// arbitrary but fixed tangent frame of the normal).
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"
#include "io/scene.h"
#include "lights/light.h"
#include "optics/transfer_function.h"
#include "render/camera.h"

namespace voxlight::pipeline {

/// Loads the scene's volume (phantom or file).
core::Volume loadSceneVolume(const io::Scene& scene, const core::Progress& progress);
/// loadSceneVolume's first check, alone (cheap: before a command's slower checks): a volume
/// file or folder the scene names that does not exist is an InputError naming the scene's key.
void checkSceneVolumeExists(const io::Scene& scene);
/// What identifies the volume's source without reading it: a phantom's name and size, or the
/// file's (or DICOM directory's files') path, size and modification time, plus the read options.
/// A changed file gets a new identity; the content hash decides what is really new.
std::uint64_t volumeIdentity(const io::Scene& scene);

/// The scene's TF for this volume (see header comment).
optics::TransferFunction buildTransferFunction(const io::Scene& scene, const core::Volume& volume);
/// InputError (transfer_function.preset) when the scene names a preset that does not exist.
void checkPresetName(const io::Scene& scene);

render::CameraSpec buildCameraSpec(const io::CameraDesc& desc);

/// A side view must show this many times the anterior view's area to be chosen by "auto".
inline constexpr double kAutoViewAreaRatio = 2.0;
/// The named view a camera uses: desc.view itself, or for "auto" the anterior view unless the
/// box of `points` (the visible matter) seen from above or from the left shows more than
/// kAutoViewAreaRatio times its anterior area — a thin axial slab (a few CT slices) is shown face
/// on from above, a sagittal one from the left. Empty when desc names no view.
std::string resolveView(const io::CameraDesc& desc, std::span<const glm::dvec3> points);

/// The scene's lights as lights::Light (environment maps are read here). Errors name
/// "lights[i].<field>".
std::vector<std::shared_ptr<const lights::Light>> buildLights(const io::Scene& scene);
/// A uniform white sky of radiance 1 (an environment light): what the global-illumination
/// isosurface shadings (voxlight iso --bake, method iso-lattice) light a scene without lights
/// with — an unoccluded Lambertian surface of albedo a then shows radiance a.
std::shared_ptr<const lights::Light> whiteSky();

/// How often buildLights read and projected an environment map, and how often it only turned the
/// last one built (same file, colour × intensity and layout; another rotation): for tests.
struct EnvironmentMapCounts {
    std::size_t builds = 0, turns = 0;
};
EnvironmentMapCounts environmentMapCounts();
/// Identity of the lights: their JSON and each environment map file's identity.
std::uint64_t lightsIdentity(const io::Scene& scene);
/// Identity of the environment lights alone (what their SH irradiance depends on).
std::uint64_t environmentLightsIdentity(const io::Scene& scene);
/// Whether one of the scene's lights is an environment map.
bool hasEnvironmentLight(const io::Scene& scene);

}  // namespace voxlight::pipeline
