// SPDX-License-Identifier: MIT
#pragma once
// Helpers shared by the hard-case tests (tests/stability/): a volume written from a voxel
// function, cheap per-method settings, a two-level TF, the finite/non-negative image check, and a
// render that either succeeds or refuses with an InputError.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/volume.h"
#include "io/volume_io.h"
#include "pipeline/pipeline.h"
#include "pipeline/registry.h"

namespace voxlight::test {

struct HardVolume {
    std::string name;
    glm::ivec3 dims;
    glm::dvec3 spacing;
    /// Value of voxel (i, j, k).
    float (*value)(int i, int j, int k);
};

/// Writes `h` as dir/<name>.nii.gz (Float32, origin 0, identity direction: voxel (i, j, k) sits at
/// (i, j, k) · spacing mm).
inline std::filesystem::path writeHard(const HardVolume& h, const std::filesystem::path& dir) {
    core::Geometry g;
    g.dims = h.dims;
    g.spacing = h.spacing;
    core::Volume v(g, core::VoxelType::Float32);
    float* d = v.dataAs<float>();
    for (int k = 0; k < h.dims.z; ++k)
        for (int j = 0; j < h.dims.y; ++j)
            for (int i = 0; i < h.dims.x; ++i) d[v.linearIndex(i, j, k)] = h.value(i, j, k);
    const auto path = dir / (h.name + ".nii.gz");
    io::writeVolume(v, path);
    return path;
}

/// A ball of value 600 (σt 0.3/mm under tfOf(0.3)) of radius 3.2 voxels around voxel (4, 4, 4) of a
/// 9³ volume, in a thin ramp (values 0..80: σt ≤ 0.12/mm): a small scene with shadows in it.
inline float ballValue(int i, int j, int k) {
    const double r2 = (i - 4.0) * (i - 4.0) + (j - 4.0) * (j - 4.0) + (k - 4.0) * (k - 4.0);
    return r2 <= 3.2 * 3.2 ? 600.f : float(10 * i);
}
inline const HardVolume kBall{"ball", {9, 9, 9}, {1, 1, 1}, ballValue};

/// Every registered method's name.
inline std::vector<std::string> allMethods() {
    std::vector<std::string> methods;
    for (const auto& m : pipeline::MethodRegistry::instance().methods()) methods.push_back(m.name);
    return methods;
}

/// Cheap settings per method, so that every case runs in well under a second.
inline nlohmann::json methodOf(const std::string& name) {
    using nlohmann::json;
    if (name == "pathtrace") return {{"name", name}, {"params", {{"spp", 2}}}};
    if (name == "sh-local" || name == "sh-global")
        return {{"name", name}, {"params", {{"rays", 16}}}};
    if (name == "ritschel") return {{"name", name}, {"params", {{"rays", 16}}}};
    if (name == "pvrt")
        return {{"name", name}, {"params", {{"resolution", 8}, {"photons", 2}, {"clusters", 4}}}};
    if (name == "iso-lattice")
        return {{"name", name}, {"params", {{"samples", 4}, {"lattice_resolution", 8}}}};
    return {{"name", name}};
}

/// White albedo, σt 0 below value 0, ramping to `sigma` [1/mm] at 200 and flat to 1000.
inline nlohmann::json tfOf(double sigma) {
    using nlohmann::json;
    const json white = {0.9, 0.9, 0.9};
    return {{"points",
             {{{"value", 0.0}, {"color", white}, {"extinction", 0.0}},
              {{"value", 200.0}, {"color", white}, {"extinction", sigma}},
              {{"value", 1000.0}, {"color", white}, {"extinction", sigma}}}}};
}

/// A 12×10 scene of `volume` under tfOf(0.3) with `method` (a method object, e.g. methodOf(name))
/// and `lights` (default: one oblique directional light).
inline nlohmann::json hardScene(const std::filesystem::path& volume, const nlohmann::json& method,
                                nlohmann::json lights = nullptr) {
    using nlohmann::json;
    if (lights.is_null())
        lights = json::array(
            {{{"type", "directional"}, {"direction", {0.3, 0.4, -0.8}}, {"intensity", 4}}});
    return {{"volume", volume.string()},
            {"transfer_function", tfOf(0.3)},
            {"method", method},
            {"lights", std::move(lights)},
            {"image", {{"width", 12}, {"height", 10}}}};
}

/// Finite, non-negative radiance and coverage in [0, 1].
inline void expectSane(const core::ImageRGBA& im, const std::string& what) {
    for (std::size_t i = 0; i < im.pixels.size(); ++i) {
        const float v = im.pixels[i];
        ASSERT_TRUE(std::isfinite(v) && v >= 0.f) << what << ": pixel value " << v << " at " << i;
        if (i % 4 == 3) {
            ASSERT_LE(v, 1.f + 1e-5f) << what << ": coverage " << v;
        }
    }
}

/// Renders the scene document `d`; nullopt (and a line saying why) when it refuses with an
/// InputError. Any other exception fails the test through gtest.
inline std::optional<pipeline::RunResult> renderOrRefuse(const nlohmann::json& d,
                                                         const std::string& what) {
    try {
        return pipeline::renderScene(io::parseScene(d, "hard.json", "."));
    } catch (const InputError& e) {
        std::printf("refused: %s: %s\n", what.c_str(), e.what());
        return std::nullopt;
    }
}

}  // namespace voxlight::test
