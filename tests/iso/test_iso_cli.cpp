// SPDX-License-Identifier: MIT
// `voxlight iso` end to end: a mesh and stats are written; bad input exits 2 with one line and
// leaves no file behind.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "io/image.h"
#include "io/volume_io.h"
#include "iso_test_util.h"
#include "sh/sh_basis.h"
#include "support/test_support.h"

namespace voxlight {
namespace {
namespace fs = std::filesystem;

struct Result {
    int code;
    std::string err;
};

Result run(const std::string& args, const fs::path& dir) {
    const fs::path errFile = dir / "stderr.txt";
    const std::string cmd =
        std::string(VOXLIGHT_BINARY) + " " + args + " >/dev/null 2>'" + errFile.string() + "'";
    const int status = std::system(cmd.c_str());
    std::ifstream ef(errFile);
    std::string err((std::istreambuf_iterator<char>(ef)), {});
    fs::remove(errFile);
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, err};
}

std::size_t lineCount(const std::string& s) {
    return std::size_t(std::count(s.begin(), s.end(), '\n'));
}

/// Nothing but the given names in `dir` (no temporaries left behind).
void expectOnly(const fs::path& dir, std::vector<std::string> names) {
    std::vector<std::string> found;
    for (const auto& e : fs::directory_iterator(dir)) found.push_back(e.path().filename().string());
    std::sort(found.begin(), found.end());
    std::sort(names.begin(), names.end());
    EXPECT_EQ(found, names);
}

fs::path writeScene(const test::TempDir& tmp, const std::string& body) {
    const fs::path p = tmp / "scene.json";
    std::ofstream(p) << body;
    return p;
}

constexpr const char* kSphere = R"({"volume": {"phantom": "sphere", "size": 24})";

TEST(IsoCli, WritesMeshAndStats) {
    test::TempDir tmp;
    const fs::path scene = writeScene(tmp, std::string(kSphere) + "}");
    const Result r = run("iso -q '" + scene.string() + "' -o '" + (tmp / "m.glb").string() +
                             "' --isovalue 0.5 --stats '" + (tmp / "st.json").string() + "'",
                         tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    expectOnly(tmp.path(), {"scene.json", "m.glb", "st.json"});
    std::ifstream in(tmp / "st.json");
    const auto j = nlohmann::json::parse(in);
    EXPECT_EQ(j["isosurface"]["isovalue"], 0.5);
    EXPECT_EQ(j["isosurface"]["isovalue_source"], "--isovalue");
    EXPECT_TRUE(j["isosurface"]["report"]["closed"].get<bool>());
    EXPECT_EQ(j["isosurface"]["report"]["self_intersections"], 0);
    EXPECT_EQ(j["isosurface"]["report"]["boundary_edges"], 0);
}

TEST(IsoCli, IsovalueComesFromTheSceneWhenNotGiven) {
    test::TempDir tmp;
    const fs::path scene =
        writeScene(tmp, std::string(kSphere) +
                            R"(, "method": {"name": "iso", "params": {"iso_value": 0.25}}})");
    const Result r = run("iso -q '" + scene.string() + "' -o '" + (tmp / "m.ply").string() +
                             "' --stats '" + (tmp / "st.json").string() + "'",
                         tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    std::ifstream in(tmp / "st.json");
    const auto j = nlohmann::json::parse(in);
    EXPECT_EQ(j["isosurface"]["isovalue"], 0.25);
    EXPECT_EQ(j["isosurface"]["isovalue_source"], "method.params.iso_value");
}

void expectBadInput(const test::TempDir& tmp, const std::string& args, const std::string& needle,
                    const std::vector<std::string>& leftOver) {
    const Result r = run(args, tmp.path());
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_EQ(lineCount(r.err), 1u) << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
    expectOnly(tmp.path(), leftOver);
}

TEST(IsoCli, IsovalueOutsideTheDataRangeNamesTheRange) {
    test::TempDir tmp;
    const fs::path scene = writeScene(tmp, std::string(kSphere) + "}");
    expectBadInput(
        tmp, "iso -q '" + scene.string() + "' -o '" + (tmp / "m.ply").string() + "' --isovalue 7",
        "--isovalue: 7 is outside the data range [0, 1]", {"scene.json"});
}

TEST(IsoCli, FlatVolumeHasNoIsosurface) {
    test::TempDir tmp;
    core::Geometry g;
    g.dims = {8, 8, 8};
    core::Volume flat(g, core::VoxelType::Int16);
    io::writeVolume(flat, tmp / "flat.nii.gz");
    expectBadInput(tmp,
                   "iso -q '" + (tmp / "flat.nii.gz").string() + "' -o '" +
                       (tmp / "m.ply").string() + "' --isovalue 0",
                   "flat", {"flat.nii.gz"});
}

TEST(IsoCli, AVolumeOneVoxelThickSaysSoInsteadOfBlamingClipPlanes) {
    // 10×1×1 voxels with values 0..9: the isovalue is inside the range, yet marching cubes has no
    // cell; the error used to blame "the clip planes and crop box", of which there were none.
    test::TempDir tmp;
    core::Geometry g;
    g.dims = {10, 1, 1};
    core::Volume line(g, core::VoxelType::Int16);
    for (int i = 0; i < 10; ++i) line.dataAs<std::int16_t>()[i] = std::int16_t(i);
    io::writeVolume(line, tmp / "line.nii.gz");
    expectBadInput(tmp,
                   "iso -q '" + (tmp / "line.nii.gz").string() + "' -o '" +
                       (tmp / "m.ply").string() + "' --isovalue 4.5",
                   "one voxel thick", {"line.nii.gz"});
}

TEST(IsoCli, UnwritableOrUnknownOutputsAreRefusedBeforeTheWork) {
    test::TempDir tmp;
    const fs::path scene = writeScene(tmp, std::string(kSphere) + "}");
    expectBadInput(tmp, "iso -q '" + scene.string() + "' -o '" + (tmp / "m.stl").string() + "'",
                   ".ply, .obj, .glb", {"scene.json"});
    expectBadInput(tmp,
                   "iso -q '" + scene.string() + "' -o '" + (tmp / "no" / "m.ply").string() + "'",
                   "does not exist", {"scene.json"});
}

TEST(IsoCli, ClipPlanesThatRemoveEverythingAreAnError) {
    test::TempDir tmp;
    const fs::path scene =
        writeScene(tmp, std::string(kSphere) +
                            R"(, "clip_planes": [{"point": [1e4, 0, 0], "normal": [1, 0, 0]}]})");
    expectBadInput(tmp, "iso -q '" + scene.string() + "' -o '" + (tmp / "m.obj").string() + "'",
                   "remove the whole isosurface", {"scene.json"});
    // Two opposite planes through one point keep a plane: with --cap, two caps on each other (a
    // closed mesh of no volume, written as one clean part).
    const fs::path flat =
        writeScene(tmp, std::string(kSphere) +
                            R"(, "clip_planes": [{"point": [0, 0, 0], "normal": [1, 0, 0]},
                                      {"point": [0, 0, 0], "normal": [-1, 0, 0]}]})");
    expectBadInput(tmp,
                   "iso -q '" + flat.string() + "' --cap -o '" + (tmp / "m.obj").string() + "'",
                   "no thickness", {"scene.json"});
}

// --cap: a crop box through the sphere phantom leaves a watertight piece, the stats say what the
// caps added; without it the same cut is open.
TEST(IsoCli, CapClosesTheCutsOfTheCropBox) {
    test::TempDir tmp;
    const fs::path scene = writeScene(
        tmp, std::string(kSphere) +
                 R"(, "crop_box": {"min": [-100, -100, -100], "max": [0.3, 0.2, 100]}})");
    for (const bool cap : {true, false}) {
        const Result r = run("iso -q '" + scene.string() + "' -o '" + (tmp / "m.ply").string() +
                                 "' --isovalue 0.5 --stats '" + (tmp / "st.json").string() + "'" +
                                 (cap ? " --cap" : ""),
                             tmp.path());
        ASSERT_EQ(r.code, 0) << r.err;
        std::ifstream in(tmp / "st.json");
        const auto j = nlohmann::json::parse(in)["isosurface"];
        EXPECT_EQ(j["report"]["closed"].get<bool>(), cap);
        EXPECT_EQ(j["report"]["self_intersections"], 0);
        if (cap) {
            EXPECT_GT(j["caps"]["triangles"].get<int>(), 0);
            EXPECT_EQ(j["caps"]["open_cut_edges"], 0);
            EXPECT_EQ(j["caps"]["failed_planes"], 0);
            EXPECT_EQ(j["report"]["boundary_edges"], 0);
        } else {
            EXPECT_TRUE(j["caps"].is_null());
        }
    }
}

/// The vertex colours of an OBJ written by voxlight (`v x y z r g b`, sRGB-encoded in [0, 1]).
std::vector<std::array<double, 3>> objColours(const fs::path& p) {
    std::ifstream in(p);
    std::vector<std::array<double, 3>> out;
    std::string tag;
    for (std::string line; std::getline(in, line);) {
        if (line.rfind("v ", 0) != 0) continue;
        std::istringstream ls(line);
        double x, y, z;
        std::array<double, 3> c;
        ls >> tag >> x >> y >> z >> c[0] >> c[1] >> c[2];
        out.push_back(c);
    }
    return out;
}

// --bake with no scene lights: a uniform white sky of radiance 1, under which an unoccluded
// (convex) surface leaves exactly its albedo — the colour of the unbaked export — whether traced
// from the vertices (the default) or read from the lattice.
TEST(IsoCli, BakedLightUnderTheDefaultSkyLeavesAConvexSurfaceItsAlbedo) {
    test::TempDir tmp;
    const fs::path scene = writeScene(tmp, std::string(kSphere) + "}");
    const std::string base = "iso -q '" + scene.string() + "' --isovalue 0.5 -o '";
    ASSERT_EQ(run(base + (tmp / "plain.obj").string() + "'", tmp.path()).code, 0);
    const auto plain = objColours(tmp / "plain.obj");
    ASSERT_GT(plain.size(), 100u);
    auto linear = [](double c) {
        return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
    };
    // (The coarsest lattice too: at 1/8 texel per voxel, once allowed, a fifth of a sphere's
    // vertices were baked black.)
    for (const std::string variant : {"vertices", "lattice", "lattice --lattice-resolution 0.5"}) {
        SCOPED_TRACE(variant);
        const std::string from = variant.substr(0, variant.find(' '));
        const Result r =
            run(base + (tmp / "lit.obj").string() + "' --bake --samples 16 --bake-from " + variant +
                    " --stats '" + (tmp / "st.json").string() + "'",
                tmp.path());
        ASSERT_EQ(r.code, 0) << r.err;
        const auto lit = objColours(tmp / "lit.obj");
        ASSERT_EQ(plain.size(), lit.size());
        // In linear terms: the mean within 0.5 % of the albedo (the lattice tests' convex
        // tolerance); each vertex loses at most one of its 16 paths (6.25 %): on the phantom's
        // ±1-voxel ramp the trilinear surface has voxel-scale facets that a grazing path can meet
        // (measured from the lattice: 12 of 1248 vertices below 0.995, the lowest 0.983).
        double sum = 0.0;
        for (std::size_t i = 0; i < lit.size(); ++i) {
            const double ratio = linear(lit[i][0]) / linear(plain[i][0]);
            ASSERT_LE(ratio, 1.0 + 1e-3) << i;
            ASSERT_GE(ratio, 1.0 - 1.0 / 16.0) << i;
            for (int c = 1; c < 3; ++c)
                ASSERT_NEAR(linear(lit[i][c]) / linear(plain[i][c]), ratio, 1e-2) << i;
            sum += ratio;
        }
        EXPECT_NEAR(sum / double(lit.size()), 1.0, 0.005);
        std::ifstream in(tmp / "st.json");
        const auto j = nlohmann::json::parse(in);
        const auto& bake = j["isosurface"]["bake"];
        EXPECT_EQ(bake["from"], from);
        EXPECT_NE(bake["lights"].get<std::string>().find("white sky"), std::string::npos);
        if (from == "lattice") {
            EXPECT_GT(bake["texels_computed"].get<int>(), 0);
            EXPECT_LT(bake["texels_computed"].get<int>(), bake["texels_full"].get<int>());
        } else {
            EXPECT_EQ(bake["paths"].get<std::size_t>(), 16 * lit.size());
        }
    }
}

TEST(IsoCli, ABakeMostlyBrighterThanWhiteSaysSoWithAnExposureThatFits) {
    // A sky of radiance 4 bakes the convex sphere at 4 × its albedo: every vertex clamped to white
    // in the export, which was said nowhere (probe: courtyard.hdr clamped 24 % of the vertices).
    test::TempDir tmp;
    core::ImageRGBA sky(16, 8);
    for (std::size_t i = 0; i < sky.pixels.size(); ++i) sky.pixels[i] = 4.f;
    io::writeImage(sky, tmp / "sky.exr");
    const fs::path scene =
        writeScene(tmp, std::string(kSphere) + R"(, "lights": [{"type": "environment", "path": ")" +
                            (tmp / "sky.exr").string() + R"("}]})");
    const std::string base = "iso -q '" + scene.string() + "' --isovalue 0.5 --bake --samples 4 ";
    const Result r = run(base + "-o '" + (tmp / "m.ply").string() + "'", tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    const std::size_t at = r.err.find("bake brighter than white");
    ASSERT_NE(at, std::string::npos) << r.err;
    const std::size_t e = r.err.find("image.exposure to ");
    ASSERT_NE(e, std::string::npos) << r.err;
    const double stops = std::stod(r.err.substr(e + 18));
    EXPECT_LT(stops, -1.0) << r.err;  // the albedo × 4: about two stops down
    const Result fitted = run(base + "--set image.exposure=" + std::to_string(stops) + " -o '" +
                                  (tmp / "m.ply").string() + "'",
                              tmp.path());
    ASSERT_EQ(fitted.code, 0) << fitted.err;
    EXPECT_EQ(fitted.err.find("brighter than white"), std::string::npos) << fitted.err;
}

// --export-sh: each vertex's SH irradiance transfer T in the PLY (read back by hand from the file,
// tests/iso/read_mesh.py). Under the default white sky a convex surface is unoccluded, so
// T_lm = Â_l · Y_lm(n) (Ramamoorthi & Hanrahan 2001: Â_0 = π, Â_1 = 2π/3) at the vertex normal n:
// band 0 exactly (every path escapes, Y_00 is constant), band 1 within its Monte-Carlo noise —
// 256 cosine-weighted paths per texel leave ≈ 7 % of the band's amplitude per texel, the 8 texels
// a vertex reads ≈ 3 %, bound on the RMS over vertices 0.08 of Â_1·max|Y_1m|. The baked colour is
// the relit transfer: red / (√(4π) · T_00,r / π) is the albedo at every vertex (the sky's SH is
// √(4π) in band 0), within 8-bit sRGB rounding (≤ 1.5 % at the sphere's mid-grey).
TEST(IsoCli, ExportedShTransferRelightsToTheBakedColours) {
    test::TempDir tmp;
    const fs::path scene = writeScene(tmp, std::string(kSphere) + "}");
    const fs::path ply = tmp / "sh.ply";
    const Result r = run("iso -q '" + scene.string() + "' --isovalue 0.5 -o '" + ply.string() +
                             "' --bake --bake-from lattice --lattice-mode sh --sh-order 2 "
                             "--samples 256 --export-sh",
                         tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    const auto back = iso::test::readMeshBack(ply, tmp.path());
    if (!back) GTEST_SKIP() << "python3-vtk9 is missing: the PLY was not read back";
    const nlohmann::json& j = *back;
    ASSERT_EQ(j["sh_names"].size(), 12u);
    EXPECT_EQ(j["sh_names"][0], "sh0_r");
    EXPECT_EQ(j["sh_names"][11], "sh3_b");
    const auto& vs = j["sh_vertices"];
    ASSERT_EQ(vs.size(), j["vertices"].get<std::size_t>());  // VTK's reader agrees on the count
    ASSERT_GT(vs.size(), 100u);
    const double pi = 3.14159265358979323846, a0 = pi, a1 = 2.0 * pi / 3.0;
    auto linear = [](double c) {
        return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
    };
    double band1Sq = 0.0, albedoMin = 1e9, albedoMax = 0.0;
    std::array<double, 4> y{};
    for (const auto& v : vs) {
        const glm::dvec3 n(v[0].get<double>(), v[1].get<double>(), v[2].get<double>());
        sh::evalShUnitDouble(1, glm::normalize(n), y);
        for (int c = 0; c < 3; ++c)
            ASSERT_NEAR(v[6 + c].get<double>(), a0 * y[0], 0.005 * a0 * y[0]);
        for (int i = 1; i < 4; ++i) {
            const double d = v[6 + 3 * i].get<double>() - a1 * y[std::size_t(i)];
            band1Sq += d * d;
        }
        const double relit = std::sqrt(4.0 * pi) * v[6].get<double>() / pi;
        const double albedo = linear(v[3].get<double>() / 255.0) / relit;
        albedoMin = std::min(albedoMin, albedo), albedoMax = std::max(albedoMax, albedo);
    }
    const double maxY1 = std::sqrt(3.0 / (4.0 * pi));
    EXPECT_LT(std::sqrt(band1Sq / (3.0 * double(vs.size()))), 0.08 * a1 * maxY1);
    EXPECT_LT(albedoMax / albedoMin, 1.03);
    // Not for the other formats, and not without the SH lattice.
    expectBadInput(tmp,
                   "iso -q '" + scene.string() + "' --isovalue 0.5 -o '" +
                       (tmp / "m.obj").string() +
                       "' --bake --bake-from lattice --lattice-mode sh --export-sh",
                   "PLY only", {"scene.json", "sh.ply", "reader.json"});
    expectBadInput(tmp,
                   "iso -q '" + scene.string() + "' --isovalue 0.5 -o '" +
                       (tmp / "m.ply").string() + "' --bake --export-sh",
                   "--bake-from lattice --lattice-mode sh",
                   {"scene.json", "sh.ply", "reader.json"});
}

TEST(IsoCli, BakeOptionsThatCannotWorkAreRefused) {
    test::TempDir tmp;
    const fs::path scene = writeScene(
        tmp, std::string(kSphere) +
                 R"(, "lights": [{"type": "point", "position": [0, 0, 100], "intensity": 1}]})");
    expectBadInput(tmp,
                   "iso -q '" + scene.string() + "' --isovalue 0.5 -o '" +
                       (tmp / "m.ply").string() + "' --bake --lattice-mode sh --bake-from lattice",
                   "distant lights only", {"scene.json"});
    expectBadInput(tmp,
                   "iso -q '" + scene.string() + "' --isovalue 0.5 -o '" +
                       (tmp / "m.ply").string() + "' --bake --lattice-mode sh --bake-from vertices",
                   "needs the lattice", {"scene.json"});
    // A bake option without --bake did nothing silently.
    for (const char* option : {"--samples 5", "--bounces 2", "--bake-from lattice"})
        expectBadInput(tmp,
                       "iso -q '" + scene.string() + "' --isovalue 0.5 -o '" +
                           (tmp / "m.ply").string() + "' " + option,
                       "takes effect only with --bake", {"scene.json"});
    // Lattice options with the vertex bake (the default), and an SH order for irradiance: the
    // mesh came out byte-identical to a plain --bake.
    for (const char* option :
         {"--lattice-resolution 4", "--lattice-texels own", "--bake-from vertices --sh-order 3"})
        expectBadInput(tmp,
                       "iso -q '" + scene.string() + "' --isovalue 0.5 -o '" +
                           (tmp / "m.ply").string() + "' --bake " + option,
                       "takes effect only with --bake-from lattice", {"scene.json"});
    expectBadInput(tmp,
                   "iso -q '" + scene.string() + "' --isovalue 0.5 -o '" +
                       (tmp / "m.ply").string() + "' --bake --bake-from lattice --sh-order 3",
                   "takes effect only with --lattice-mode sh", {"scene.json"});
    // Texels too coarse to reach the surface (kMinLatticeResolution).
    expectBadInput(tmp,
                   "iso -q '" + scene.string() + "' --isovalue 0.5 -o '" +
                       (tmp / "m.ply").string() +
                       "' --bake --bake-from lattice --lattice-resolution 0.25",
                   "--lattice-resolution", {"scene.json"});
    // NaN passed every range check: --max-memory-mb nan turned the size guard off (probe).
    for (const char* option :
         {"--max-memory-mb nan", "--bake --bake-from lattice --lattice-resolution nan",
          "--max-memory-mb inf"})
        expectBadInput(tmp,
                       "iso -q '" + scene.string() + "' --isovalue 0.5 -o '" +
                           (tmp / "m.ply").string() + "' " + option,
                       "is not a finite number", {"scene.json"});
    // A negative minimum wrapped to a huge one: "the clean-up removed every face".
    expectBadInput(tmp,
                   "iso -q '" + scene.string() + "' --isovalue 0.5 -o '" +
                       (tmp / "m.ply").string() + "' --min-component-faces -1",
                   "--min-component-faces", {"scene.json"});
}

TEST(IsoCli, DecimationThatFoldsTheMeshWarns) {
    // The abdominal CT at 300 HU decimated to 5000 faces: 2736 self-intersecting pairs on 7689
    // faces, area +22 %, said only by the report's count (probe). Past kFoldedShare: a warning.
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/example_ct.nii.gz");
    test::TempDir tmp;
    const std::string base = "iso '" + ct.string() + "' --isovalue 300 -o '" +
                             (tmp / "m.ply").string() + "' --decimate ";
    const Result folded = run(base + "5000", tmp.path());
    ASSERT_EQ(folded.code, 0) << folded.err;
    EXPECT_NE(folded.err.find("warning: --decimate 5000 folded the mesh"), std::string::npos)
        << folded.err;
    const Result mild = run(base + "60000", tmp.path());
    ASSERT_EQ(mild.code, 0) << mild.err;
    EXPECT_EQ(mild.err.find("folded the mesh"), std::string::npos) << mild.err;
}

TEST(IsoCli, SmoothingACappedCutOfARealCtKeepsItNearlyFreeOfSelfIntersections) {
    // The abdominal CT at 300 HU cut at a voxel plane, capped, 5 smoothing iterations: 14
    // self-intersecting pairs before the cap's vertices were held, 29 with them held alone
    // (surface vertices next to the rim moved across the cap), 3 when no move crosses a capped
    // plane; deterministic.
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/example_ct.nii.gz");
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json")
        << R"({"volume": ")" << ct.string()
        << R"(", "clip_planes": [{"point": [57.956329, 0, 0], "normal": [1, 0, 0]}]})";
    const Result r = run("iso '" + (tmp / "scene.json").string() +
                             "' --isovalue 300 --cap "
                             "--smooth 5 -o '" +
                             (tmp / "m.ply").string() + "'",
                         tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    const std::size_t at = r.err.find("self-intersections ");
    ASSERT_NE(at, std::string::npos) << r.err;
    constexpr int kMostPairs = 5;  // measured 3
    EXPECT_LE(std::atoi(r.err.c_str() + at + 19), kMostPairs) << r.err;
}

}  // namespace
}  // namespace voxlight
