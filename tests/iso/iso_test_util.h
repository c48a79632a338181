// SPDX-License-Identifier: MIT
#pragma once
// Analytic volumes for the iso/ tests: fields whose isosurfaces are known spheres.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/volume.h"
#include "iso/extract.h"
#include "iso/mesh.h"

namespace voxlight::iso::test {

struct Ball {
    glm::dvec3 centre;
    double radius;
};

/// Float volume whose value at each voxel is f(world position in mm).
template <class F>
core::Volume fieldVolume(const core::Geometry& g, F&& f, const char* description = "field") {
    core::Volume v(g, core::VoxelType::Float32);
    float* d = v.dataAs<float>();
    for (int k = 0; k < g.dims.z; ++k)
        for (int j = 0; j < g.dims.y; ++j)
            for (int i = 0; i < g.dims.x; ++i)
                d[v.linearIndex(i, j, k)] = float(f(g.indexToWorld({i, j, k})));
    v.description = description;
    return v;
}

/// Float volume whose value is max over balls of (radius − |x − centre|) (world mm): the isovalue-0
/// surface is the union of the spheres; each value is the signed distance to the nearest sphere, so
/// linear interpolation along grid edges places vertices within O(h²/R) of it.
inline core::Volume ballsVolume(const core::Geometry& g, const std::vector<Ball>& balls) {
    return fieldVolume(
        g,
        [&](const glm::dvec3& p) {
            double s = -1e30;
            for (const Ball& b : balls) s = std::max(s, b.radius - glm::length(p - b.centre));
            return s;
        },
        "balls");
}

inline glm::dvec3 toGlm(const OpenMesh::Vec3d& p) { return {p[0], p[1], p[2]}; }

/// Extraction at `isovalue` with vertex colour `color`, no clipping.
inline ExtractOptions at(double isovalue, glm::vec3 color = glm::vec3(1.f)) {
    ExtractOptions o;
    o.isovalue = isovalue;
    o.color = color;
    return o;
}

/// Reads an exported mesh back with tests/iso/read_mesh.py (VTK's readers and the file by hand);
/// nullopt (the caller skips) when python3-vtk9 is missing.
inline std::optional<nlohmann::json> readMeshBack(const std::filesystem::path& file,
                                                  const std::filesystem::path& dir) {
    const std::filesystem::path outFile = dir / "reader.json";
    const std::string cmd = "/usr/bin/python3 '" + std::string(VOXLIGHT_ISO_READER) + "' '" +
                            file.string() + "' > '" + outFile.string() + "'";
    const int status = std::system(cmd.c_str());
    if (WIFEXITED(status) && WEXITSTATUS(status) == 77) return std::nullopt;
    EXPECT_EQ(status, 0) << cmd;
    std::ifstream in(outFile);
    return nlohmann::json::parse(in);
}

}  // namespace voxlight::iso::test
