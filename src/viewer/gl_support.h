// SPDX-License-Identifier: MIT
#pragma once
// Which scenes the viewer's GLSL ray caster (shaders/raycast.frag, viewer/gl_ray_caster.h)
// evaluates as the CPU ray caster does, and in words why not the others — no OpenGL here, so the
// rule is tested without a window. A scene the GL path cannot do is shown by the CPU path, and the
// stats panel says why.
#include <string>

#include "pipeline/pipeline.h"

namespace voxlight::viewer {

/// Lights (after the headlight a scene without lights gets) and clip planes the shader holds
/// (its uniform arrays: kMaxLights, kMaxClipPlanes in shaders/raycast.frag).
inline constexpr int kMaxGlLights = 8;
inline constexpr int kMaxGlClipPlanes = 8;
/// SH methods: faces that remove matter for the light (the clip planes and the crop box's six;
/// kMaxShFaces in shaders/raycast.frag) and point lights (kMaxShPoints; directional and
/// environment lights are summed into constants on the CPU, any number of them).
inline constexpr int kMaxGlShFaces = kMaxGlClipPlanes + 6;
inline constexpr int kMaxGlShPointLights = kMaxGlLights;
/// The longest pre-integrated step (voxels) the shader takes as the CPU does: the CPU marcher
/// refines longer segments (render/dvr_march.h), the shader does not (the 1.001 is the CPU's
/// rounding margin).
inline constexpr double kGlMaxStepVoxels = 1.0 / 1.001;

/// Which renderer draws the viewer's image: the measurement at start-up picks (Auto), or the user
/// forces one (`voxlight view --renderer gpu|cpu|auto`).
enum class RendererChoice { Auto, Gpu, Cpu };
/// "auto" | "gpu" | "cpu"; throws InputError (source "command line", field "--renderer").
RendererChoice rendererChoiceFromString(const std::string& name);
std::string toString(RendererChoice c);

/// Empty when the GLSL ray caster renders `setup` (method `setup.method`) as the CPU ray caster
/// would; else one line saying why not. `setup` null: the scene's method does not render with
/// the CPU ray caster at all (pipeline::Session::prepare returned nothing), `method` names it.
std::string glUnsupportedReason(const std::string& method, const pipeline::CasterSetup* setup);

}  // namespace voxlight::viewer
