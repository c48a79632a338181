// SPDX-License-Identifier: MIT
#include "viewer/gl_support.h"

#include "core/error.h"
#include "lights/environment_light.h"

namespace voxlight::viewer {

RendererChoice rendererChoiceFromString(const std::string& name) {
    if (name == "auto") return RendererChoice::Auto;
    if (name == "gpu") return RendererChoice::Gpu;
    if (name == "cpu") return RendererChoice::Cpu;
    throw InputError("command line", "--renderer", "'" + name + "' is not a renderer",
                     "choose one of: auto, gpu, cpu");
}

std::string toString(RendererChoice c) {
    switch (c) {
        case RendererChoice::Auto:
            return "auto";
        case RendererChoice::Gpu:
            return "gpu";
        case RendererChoice::Cpu:
            return "cpu";
    }
    return "?";
}

std::string glUnsupportedReason(const std::string& method, const pipeline::CasterSetup* setup) {
    const std::string only =
        "the GLSL ray caster does methods 'gradient', 'emission-absorption', 'sh-local', "
        "'sh-global' and 'ritschel' only";
    const bool sh = method == "sh-local" || method == "sh-global" || method == "ritschel";
    if (!setup || (method != "gradient" && method != "emission-absorption" && !sh))
        return "method '" + method + "' is rendered on the CPU: " + only;
    const render::RenderOptions& o = setup->options;
    if (sh) {
        const pipeline::CasterSetup::ShFields& f = setup->sh;
        if (!f.local && !f.global && !f.hierarchical)
            return "method '" + method + "': no SH visibility field was prepared";
        int points = 0, directional = 0;
        for (const auto& l : o.lights)
            if (dynamic_cast<const lights::PointLight*>(l.get()))
                ++points;
            else if (dynamic_cast<const lights::DirectionalLight*>(l.get()) ||
                     dynamic_cast<const lights::EnvironmentLight*>(l.get()))
                ++directional;  // an environment's dominant direction is traced as one
        if (o.shNearShadow && directional > kMaxGlLights)
            return std::to_string(directional) +
                   " directional and environment lights with near_shadow: the GLSL SH shading "
                   "traces at most " +
                   std::to_string(kMaxGlLights);
        if (points > kMaxGlShPointLights)
            return std::to_string(points) + " point lights: the GLSL SH shading holds at most " +
                   std::to_string(kMaxGlShPointLights);
    } else if (o.mode != render::Mode::Gradient && o.mode != render::Mode::EmissionAbsorption) {
        return "render mode '" + render::toString(o.mode) + "': " + only;
    }
    if (!sh && o.mode == render::Mode::Gradient) {
        int lights = 0;
        for (const auto& l : o.lights) {
            if (dynamic_cast<const lights::EnvironmentLight*>(l.get()))
                return "an environment light: its SH irradiance is shaded on the CPU only";
            ++lights;
        }
        if (lights > kMaxGlLights)
            return std::to_string(lights) + " lights: the GLSL ray caster holds at most " +
                   std::to_string(kMaxGlLights);
        if (!o.centralDifferences)
            return "forward-difference gradients (central_differences false): the GLSL ray "
                   "caster takes central differences only";
    }
    if (int(o.clipPlanes.size()) > kMaxGlClipPlanes)
        return std::to_string(o.clipPlanes.size()) +
               " clip planes: the GLSL ray caster holds at most " +
               std::to_string(kMaxGlClipPlanes);
    // The CPU marcher splits pre-integrated segments longer than a voxel where the value profile
    // is not linear (dvr_march.h kLinearityFraction); the shader does not.
    if (o.preintegrated && double(o.stepVoxels) > kGlMaxStepVoxels)
        return "a step over one voxel: the CPU ray caster refines such segments, the GLSL ray "
               "caster does not";
    return {};
}

}  // namespace voxlight::viewer
