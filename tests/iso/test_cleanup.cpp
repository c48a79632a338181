// SPDX-License-Identifier: MIT
// Clean-up: keep the k largest components / drop small ones on a two-sphere volume; decimation and
// smoothing keep a closed manifold; colours follow their vertices.
#include <gtest/gtest.h>

#include "core/error.h"
#include "iso/cleanup.h"
#include "iso/extract.h"
#include "iso_test_util.h"

namespace voxlight::iso {
namespace {
using test::Ball;
using test::toGlm;

/// Vertices of the kept ball against its radius (same reasoning as test_extract's kRadiusTol, at
/// 1 mm voxels).
constexpr double kRadiusTol = 0.03;

core::Volume twoBalls(Ball& big, Ball& small) {
    core::Geometry g;
    g.dims = {48, 32, 32};
    big = {{14.0, 15.5, 15.5}, 10.0};
    small = {{36.0, 15.5, 15.5}, 5.0};
    return test::ballsVolume(g, {big, small});
}

TEST(Cleanup, KeepsTheLargestComponentOfTwoSpheres) {
    Ball big, small;
    const core::Volume v = twoBalls(big, small);
    Extraction ex = extractIsosurface(v, test::at(0.0, {0.2f, 0.4f, 0.6f}));
    EXPECT_EQ(reportMesh(ex.mesh, false).components, 2u);
    const CleanupStats cs = cleanUp(ex.mesh, {.keepLargest = 1});
    EXPECT_EQ(cs.componentsRemoved, 1u);
    const MeshReport r = reportMesh(ex.mesh, false);
    EXPECT_EQ(r.components, 1u);
    EXPECT_TRUE(r.closed);
    for (const auto vh : ex.mesh.vertices()) {
        ASSERT_NEAR(glm::length(toGlm(ex.mesh.point(vh)) - big.centre), big.radius, kRadiusTol);
        ASSERT_EQ(ex.mesh.color(vh), Mesh::Color(0.2f, 0.4f, 0.6f));
        // Normals survive the round trip through CGAL (no vertex moved): still outward.
        const glm::dvec3 radial = glm::normalize(toGlm(ex.mesh.point(vh)) - big.centre);
        ASSERT_GT(glm::dot(toGlm(ex.mesh.normal(vh)), radial), 0.99);
    }
}

TEST(Cleanup, DropsComponentsBelowASize) {
    Ball big, small;
    const core::Volume v = twoBalls(big, small);
    Extraction ex = extractIsosurface(v, test::at(0.0));
    std::size_t smallFaces = 0;
    for (const auto fh : ex.mesh.faces()) {
        const glm::dvec3 p = toGlm(ex.mesh.point(*ex.mesh.fv_begin(fh)));
        smallFaces += glm::length(p - small.centre) < small.radius + 1.0;
    }
    // Threshold just above the small sphere's face count: only the small one goes.
    CleanupOptions o;
    o.minComponentFaces = smallFaces + 1;
    cleanUp(ex.mesh, o);
    EXPECT_EQ(ex.mesh.n_faces() + smallFaces, extractIsosurface(v, test::at(0.0)).mesh.n_faces());
    EXPECT_EQ(reportMesh(ex.mesh, false).components, 1u);
}

TEST(Cleanup, DecimationAndSmoothingKeepAClosedManifold) {
    Ball big, small;
    const core::Volume v = twoBalls(big, small);
    Extraction ex = extractIsosurface(v, test::at(0.0));
    const std::size_t before = ex.mesh.n_faces();
    CleanupOptions o;
    o.removeDegenerate = true;
    o.smoothIterations = 2;
    o.targetFaces = before / 4;
    const CleanupStats cs = cleanUp(ex.mesh, o);
    EXPECT_TRUE(cs.verticesMoved);
    setGradientNormals(ex.mesh, v);
    // Edge collapse stops on an edge count (cleanup.h): within a few faces of the target.
    EXPECT_NEAR(double(ex.mesh.n_faces()), double(before / 4), 0.02 * double(before / 4));
    const MeshReport r = reportMesh(ex.mesh, true);
    EXPECT_TRUE(r.closed);
    EXPECT_EQ(r.nonManifoldVertices, 0u);
    EXPECT_EQ(r.components, 2u);
    EXPECT_EQ(r.selfIntersections, 0);
    for (const auto vh : ex.mesh.vertices()) ASSERT_NEAR(ex.mesh.normal(vh).norm(), 1.f, 1e-5f);
}

/// Taubin smoothing of a sphere against the sphere: a low-pass filter barely moves an already smooth
/// surface (measured: area and volume change < 0.2 % after 10 iterations at R = 10 voxels).
constexpr double kSmoothedSphereTol = 0.01;

TEST(Cleanup, TaubinSmoothingMovesVerticesButDoesNotShrinkASphere) {
    Ball big, small;
    const core::Volume v = twoBalls(big, small);
    Extraction ex = extractIsosurface(v, test::at(0.0));
    const MeshReport before = reportMesh(ex.mesh, false);
    const Mesh original = ex.mesh;
    CleanupOptions o;
    o.smoothIterations = 10;
    EXPECT_TRUE(cleanUp(ex.mesh, o).verticesMoved);
    const MeshReport after = reportMesh(ex.mesh, true);
    EXPECT_NEAR(after.areaMm2 / before.areaMm2, 1.0, kSmoothedSphereTol);
    EXPECT_NEAR(after.volumeMm3 / before.volumeMm3, 1.0, kSmoothedSphereTol);
    EXPECT_TRUE(after.closed);
    EXPECT_EQ(after.selfIntersections, 0);
    double moved = 0.0;
    for (const auto vh : ex.mesh.vertices())
        moved = std::max(moved, (ex.mesh.point(vh) - original.point(vh)).norm());
    EXPECT_GT(moved, 1e-3);
}

/// The larger of twoBalls() cut 4.3 voxels past its centre, capped: what the capped-cut tests
/// smooth and decimate.
struct CappedBall {
    Ball big, small;
    core::Volume v;
    core::HalfSpace plane;
    ExtractOptions e;
    CappedBall() : v(twoBalls(big, small)), e(test::at(0.0)) {
        e.cap = true;
        plane = {{big.centre.x + 4.3, 0.0, 0.0}, {1.0, 0.0, 0.0}};
        e.keep = {plane};
    }
};

TEST(Cleanup, SmoothingACappedCutKeepsTheCapFlatAndTheMeshFreeOfSelfIntersections) {
    // A cap is a fan of rim-to-rim triangles: smoothing averaged rim vertices over those long
    // edges and dragged them across the cap (probe: 237 self-intersecting pairs after one
    // iteration on a capped sphere, 68 after 20; the mesh 0.12 mm past the plane). With the cut's
    // plane held, the rim stays on it and the mesh stays clean.
    const CappedBall c;
    const core::Volume& v = c.v;
    const ExtractOptions& e = c.e;
    const core::HalfSpace& plane = c.plane;
    for (const int iterations : {1, 5, 20}) {
        Extraction ex = extractIsosurface(v, e);
        ASSERT_EQ(reportMesh(ex.mesh, true).selfIntersections, 0);
        CleanupOptions o;
        o.smoothIterations = iterations;
        o.heldPlanes = ex.planes;
        cleanUp(ex.mesh, o);
        const MeshReport r = reportMesh(ex.mesh, true);
        EXPECT_TRUE(r.closed) << iterations;
        EXPECT_EQ(r.selfIntersections, 0) << iterations;
        std::size_t onPlane = 0;
        for (const auto vh : ex.mesh.vertices()) {
            const double d = plane.distance(toGlm(ex.mesh.point(vh)));
            ASSERT_GE(d, -kOnCapPlaneMm) << iterations;
            onPlane += std::abs(d) <= kOnCapPlaneMm;
        }
        EXPECT_GT(onPlane, 20u) << iterations;
    }
}

TEST(Cleanup, ACappedCutSmoothedOrDecimatedKeepsItsCapFlatAndShadedFromItsSide) {
    // After --smooth or --decimate the normals were all gradients again: the rim's bisector lost,
    // every cap face's vertex normals turned away from it (probe: 334 of 334 cap faces, the cap
    // shaded edge-on), and decimation bent the cap 0.01 mm off its plane.
    const CappedBall c;
    const core::Volume& v = c.v;
    const ExtractOptions& e = c.e;
    const core::HalfSpace& plane = c.plane;
    for (const bool decimate : {false, true}) {
        SCOPED_TRACE(decimate ? "decimated" : "smoothed");
        Extraction ex = extractIsosurface(v, e);
        CleanupOptions o;
        if (decimate)
            o.targetFaces = ex.mesh.n_faces() / 4;
        else
            o.smoothIterations = 10;
        o.heldPlanes = ex.planes;
        cleanUp(ex.mesh, o);
        setGradientNormals(ex.mesh, v, ex.planes, kOnCapPlaneMm);
        std::size_t capFaces = 0;
        for (const auto f : ex.mesh.faces()) {
            std::array<glm::dvec3, 3> p;
            bool onCap = true;
            int k = 0;
            for (const auto w : ex.mesh.fv_range(f)) {
                p[k] = toGlm(ex.mesh.point(w));
                onCap = onCap && std::abs(plane.distance(p[k])) <= kOnCapPlaneMm;
                ++k;
            }
            if (!onCap) continue;
            ++capFaces;
            const glm::dvec3 n = glm::normalize(glm::cross(p[1] - p[0], p[2] - p[0]));
            EXPECT_NEAR(glm::dot(n, -plane.normal), 1.0, 1e-6) << "a cap face faces the cut";
            for (const auto w : ex.mesh.fv_range(f))
                EXPECT_GT(glm::dot(toGlm(ex.mesh.normal(w)), n), 0.5)
                    << "vertex normals within 60° of the cap's (the bisector: 45° at a "
                       "right-angled rim)";
        }
        EXPECT_GT(capFaces, 10u);
        // Nothing past the plane: the cap stayed where it was cut.
        for (const auto vh : ex.mesh.vertices())
            ASSERT_GE(plane.distance(toGlm(ex.mesh.point(vh))), -kOnCapPlaneMm);
    }
}

// The limit of --smooth on shapes large and small: a small blob's size is a high frequency of the
// filter (a one-voxel blob shrank to a point in 50 iterations). Closed components keep their volume
// (cleanup.cpp: δ = lost volume / sweep rate, a few Newton passes per iteration): each ball on its
// own within kKeptVolumeTol — double rounding of the faces' sum; a δ off by 2× leaves (½)⁴ of each
// iteration's loss, measured to be far above it (below) — the blob within kBlobVolumeTol.
constexpr double kKeptVolumeTol = 1e-9;
constexpr double kBlobVolumeTol = 1e-6;

TEST(Cleanup, LongSmoothingKeepsLargeAndSmallShapesTheirVolume) {
    core::Geometry g;
    g.dims = {32, 32, 32};
    for (const double radius : {10.0, 3.0}) {
        SCOPED_TRACE(radius);
        const core::Volume v = test::ballsVolume(g, {{{15.5, 15.5, 15.5}, radius}});
        Extraction ex = extractIsosurface(v, test::at(0.0));
        const MeshReport before = reportMesh(ex.mesh, false);
        CleanupOptions o;
        o.smoothIterations = kMaxSmoothIterations;
        cleanUp(ex.mesh, o);
        const MeshReport after = reportMesh(ex.mesh, true);
        EXPECT_NEAR(after.volumeMm3 / before.volumeMm3, 1.0, kKeptVolumeTol);
        EXPECT_EQ(after.selfIntersections, 0);
    }
    // A single voxel above the isovalue: an octahedron.
    g.dims = {5, 5, 5};
    core::Volume blob(g, core::VoxelType::Float32);
    blob.dataAs<float>()[blob.linearIndex(2, 2, 2)] = 1.f;
    Extraction b = extractIsosurface(blob, test::at(0.5));
    const MeshReport b0 = reportMesh(b.mesh, false);
    ASSERT_TRUE(b0.closed);
    CleanupOptions o;
    o.smoothIterations = kMaxSmoothIterations;
    cleanUp(b.mesh, o);
    const MeshReport b1 = reportMesh(b.mesh, false);
    EXPECT_NEAR(b1.volumeMm3 / b0.volumeMm3, 1.0, kBlobVolumeTol);
    EXPECT_GT(b1.areaMm2, 0.5 * b0.areaMm2);
    // More than the limit is refused by the library too, not only by the command line.
    o.smoothIterations = kMaxSmoothIterations + 1;
    EXPECT_THROW(cleanUp(b.mesh, o), InputError);
}

}  // namespace
}  // namespace voxlight::iso
