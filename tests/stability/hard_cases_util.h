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
