// SPDX-License-Identifier: MIT
// Exports read back by an independent reader (read_mesh.py: VTK's PLY/OBJ/glTF readers, and the
// files' colour fields parsed with Python's standard library): same vertex and face counts, same
// colours in each format's documented encoding, and the documented frame.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>

#include "core/phantoms.h"
#include "iso/export.h"
#include "iso/extract.h"
#include "iso_test_util.h"
#include "support/test_support.h"

namespace voxlight::iso {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

/// Linear albedo used as the vertex colour: not a grey, and not at the ends of the sRGB curve.
const glm::vec3 kColour{0.8f, 0.5f, 0.2f};

class Export : public ::testing::Test {
  protected:
    void SetUp() override {
        const core::Volume v = core::makePhantom("sphere", {.size = 20});
        mesh_ = extractIsosurface(v, test::at(0.5, kColour)).mesh;
        ASSERT_GT(mesh_.n_faces(), 100u);
    }
    fs::path write(const std::string& name) {
        const fs::path p = tmp_ / name;
        writeMesh(mesh_, p, *meshFormatFor(p), {"test sphere", 0.5, ""});
        return p;
    }
    ::voxlight::test::TempDir tmp_;
    Mesh mesh_;
};

TEST_F(Export, PlyReadsBackWithCountsNormalsAndSrgbColours) {
    const auto r = test::readMeshBack(write("s.ply"), tmp_.path());
    if (!r) GTEST_SKIP() << "/usr/bin/python3 lacks python3-vtk9 (tools/setup.sh)";
    EXPECT_EQ((*r)["vertices"], mesh_.n_vertices());
    EXPECT_EQ((*r)["faces"], mesh_.n_faces());
    EXPECT_TRUE((*r)["has_normals"].get<bool>());
    ASSERT_EQ((*r)["colours"].size(), 1u);
    for (int c = 0; c < 3; ++c)
        EXPECT_EQ((*r)["colours"][0][c].get<int>(), std::lround(255.f * srgbEncode(kColour[c])));
}

TEST_F(Export, ObjReadsBackWithCountsAndColours) {
    const auto r =
        test::readMeshBack(write("s.OBJ"), tmp_.path());  // extensions are case-insensitive
    if (!r) GTEST_SKIP() << "/usr/bin/python3 lacks python3-vtk9 (tools/setup.sh)";
    EXPECT_EQ((*r)["vertices"], mesh_.n_vertices());
    EXPECT_EQ((*r)["faces"], mesh_.n_faces());
    EXPECT_TRUE((*r)["has_normals"].get<bool>());
    ASSERT_EQ((*r)["colours"].size(), 1u);
    for (int c = 0; c < 3; ++c)
        EXPECT_NEAR((*r)["colours"][0][c].get<double>(), srgbEncode(kColour[c]), 1e-4);
    bool frame = false;
    for (const auto& line : (*r)["comments"])
        frame = frame || line.get<std::string>().find("patient LPS") != std::string::npos;
    EXPECT_TRUE(frame) << (*r)["comments"];
}

TEST_F(Export, GlbReadsBackWithLinearColoursAndTheDocumentedNodeMatrix) {
    const auto r = test::readMeshBack(write("s.glb"), tmp_.path());
    if (!r) GTEST_SKIP() << "/usr/bin/python3 lacks python3-vtk9 (tools/setup.sh)";
    EXPECT_EQ((*r)["vertices"], mesh_.n_vertices());
    EXPECT_EQ((*r)["faces"], mesh_.n_faces());
    EXPECT_EQ((*r)["attributes"], json({"COLOR_0", "NORMAL", "POSITION"}));
    ASSERT_EQ((*r)["colours"].size(), 1u);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR((*r)["colours"][0][c].get<double>(), kColour[c], 1e-5);
    EXPECT_EQ((*r)["matrix"], json({0.001, 0, 0, 0, 0, 0, -0.001, 0, 0, 0.001, 0, 0, 0, 0, 0, 1}));
    EXPECT_EQ((*r)["extras"]["units"], "mm");
    EXPECT_EQ((*r)["extras"]["frame"], "LPS");
}

TEST(ExportFormat, ChosenByExtension) {
    EXPECT_EQ(meshFormatFor("a.PLY"), MeshFormat::Ply);
    EXPECT_EQ(meshFormatFor("a.glb"), MeshFormat::Glb);
    EXPECT_FALSE(meshFormatFor("a.stl").has_value());
    EXPECT_FALSE(meshFormatFor("ply").has_value());
}

}  // namespace
}  // namespace voxlight::iso
