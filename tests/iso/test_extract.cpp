// SPDX-License-Identifier: MIT
// Extraction: closed sphere isosurfaces (watertight, 2-manifold, area and volume against the
// analytic sphere), world coordinates under spacing/origin/direction, outward normals, clipping,
// integer isovalues on integer data, and the isovalue-range errors.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/phantoms.h"
#include "iso/cleanup.h"
#include "iso/extract.h"
#include "iso_test_util.h"

namespace voxlight::iso {
namespace {
using test::Ball;
using test::toGlm;

/// The sphere phantom's resolution: 64³ puts ≈ 22 voxels on the radius, where marching-cubes
/// faceting changes area by −0.06 % and volume by −0.12 % (measured), well inside the 1 % of the
/// issue; 32³ (≈ 11 voxels) would still pass but with less margin.
constexpr int kSpherePhantomSize = 64;
/// Area and enclosed volume against 4πr² and 4/3πr³ (issue #14's figure).
constexpr double kSphereMeasureTol = 0.01;
/// Vertices of a distance-field sphere against its radius: linear interpolation along an edge of
/// length h ≤ 1.3 mm of |x − c| misplaces the crossing by at most ≈ h²/(8R) ≈ 0.015 mm at R = 14 mm;
/// float storage adds < 1e-5 mm.
constexpr double kRadiusTol = 0.03;
/// Unit normals from the interpolated central-difference gradient against the exact radial
/// direction: central differences of |x − c| over 2h at R ≥ 14 h/1.3 deviate < 1°.
constexpr double kNormalCosTol = 0.999;

TEST(Extract, SpherePhantomIsClosedManifoldWithAnalyticAreaAndVolume) {
    const core::Volume v = core::makePhantom("sphere", {.size = kSpherePhantomSize});
    const core::SphereFacts s = core::spherePhantomFacts(v.geometry());
    const Extraction ex = extractIsosurface(v, test::at(0.5));
    EXPECT_EQ(ex.stats.rejectedFaces, 0u);
    EXPECT_FALSE(ex.stats.nudged);  // float data
    const MeshReport r = reportMesh(ex.mesh, true);
    EXPECT_EQ(r.boundaryEdges, 0u);
    EXPECT_EQ(r.nonManifoldVertices, 0u);
    EXPECT_EQ(r.selfIntersections, 0);
    EXPECT_EQ(r.components, 1u);
    ASSERT_TRUE(r.closed);
    const double area = 4.0 * std::numbers::pi * s.radius * s.radius;
    const double volume = area * s.radius / 3.0;
    EXPECT_NEAR(r.areaMm2 / area, 1.0, kSphereMeasureTol) << r;
    EXPECT_NEAR(r.volumeMm3 / volume, 1.0, kSphereMeasureTol) << r;
    // Closed 2-manifold genus 0: V − E + F = 2.
    EXPECT_EQ(long(ex.mesh.n_vertices()) - long(ex.mesh.n_edges()) + long(ex.mesh.n_faces()), 2);
}

TEST(Extract, NormalsPointOutwardAndWindingAgrees) {
    const core::Volume v = core::makePhantom("sphere", {.size = 32});
    const core::SphereFacts s = core::spherePhantomFacts(v.geometry());
    const Extraction ex = extractIsosurface(v, test::at(0.5));
    ASSERT_GT(ex.mesh.n_vertices(), 100u);
    for (const auto vh : ex.mesh.vertices()) {
        const glm::dvec3 radial = glm::normalize(toGlm(ex.mesh.point(vh)) - s.centre);
        ASSERT_GT(glm::dot(toGlm(ex.mesh.normal(vh)), radial), 0.99);
    }
    // Faces wound counter-clockwise seen from outside: the enclosed volume comes out positive.
    EXPECT_GT(reportMesh(ex.mesh, false).volumeMm3, 0.0);
}

/// A grid with non-unit spacing, an origin and a direction that rotates *and* mirrors (det −1,
/// which reverses VTK's winding in world space).
core::Geometry obliqueGeometry() {
    core::Geometry g;
    g.dims = {36, 30, 40};
    g.spacing = {0.9, 1.3, 0.8};
    g.origin = {-40.0, 25.0, 110.0};
    const double a = 0.5;  // radians about z, then x mirrored
    const glm::dmat3 rot(glm::dvec3(std::cos(a), std::sin(a), 0),
                         glm::dvec3(-std::sin(a), std::cos(a), 0), glm::dvec3(0, 0, 1));
    const glm::dmat3 mirror(glm::dvec3(-1, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1));
    g.direction = mirror * rot;
    g.validate();
    return g;
}

TEST(Extract, WorldCoordinatesHonourSpacingOriginAndDirection) {
    const core::Geometry g = obliqueGeometry();
    // A ball centred in the grid (in world mm), radius well inside.
    const Ball b{g.indexToWorld({17.5, 14.0, 19.0}), 11.0};
    const core::Volume v = test::ballsVolume(g, {b});
    const Extraction ex = extractIsosurface(v, test::at(0.0));
    ASSERT_GT(ex.mesh.n_vertices(), 500u);
    glm::dvec3 mean(0.0);
    for (const auto vh : ex.mesh.vertices()) {
        const glm::dvec3 p = toGlm(ex.mesh.point(vh));
        ASSERT_NEAR(glm::length(p - b.centre), b.radius, kRadiusTol)
            << p.x << " " << p.y << " " << p.z;
        ASSERT_GT(glm::dot(toGlm(ex.mesh.normal(vh)), glm::normalize(p - b.centre)), kNormalCosTol);
        mean += p;
    }
    mean /= double(ex.mesh.n_vertices());
    EXPECT_NEAR(glm::length(mean - b.centre), 0.0, 0.1);
    const MeshReport r = reportMesh(ex.mesh, false);
    EXPECT_TRUE(r.closed);
    EXPECT_GT(r.volumeMm3, 0.0)
        << "winding must follow the outward normals under a mirroring direction";
}

TEST(Extract, ClipPlaneRemovesTheOtherHalfWithAnOpenCut) {
    const core::Volume v = core::makePhantom("sphere", {.size = 32});
    const core::SphereFacts s = core::spherePhantomFacts(v.geometry());
    ExtractOptions o = test::at(0.5);
    // Keep x ≥ centre.x + 0.3 mm (off the grid's symmetry plane, so the cut crosses triangles).
    const glm::dvec3 p = s.centre + glm::dvec3(0.3, 0, 0);
    o.keep.push_back({p, {1.0, 0.0, 0.0}});
    const Extraction full = extractIsosurface(v, test::at(0.5));
    const Extraction half = extractIsosurface(v, o);
    for (const auto vh : half.mesh.vertices()) ASSERT_GE(toGlm(half.mesh.point(vh)).x, p.x - 1e-9);
    const MeshReport rf = reportMesh(full.mesh, false), rh = reportMesh(half.mesh, false);
    EXPECT_GT(rh.boundaryEdges, 0u);  // open cut: a rim, no cap
    EXPECT_EQ(rh.nonManifoldVertices, 0u);
    EXPECT_EQ(rh.components, 1u);
    // Every rim vertex lies on the plane.
    for (const auto eh : half.mesh.edges())
        if (half.mesh.is_boundary(eh))
            for (int k = 0; k < 2; ++k) {
                const auto vh = half.mesh.to_vertex_handle(half.mesh.halfedge_handle(eh, k));
                ASSERT_NEAR(toGlm(half.mesh.point(vh)).x, p.x, 1e-9);
            }
    // Area of the kept cap: 2πR·(R − 0.3) of the full sphere's 4πR², to the faceting tolerance.
    const double expected = (s.radius - 0.3) / (2.0 * s.radius);
    EXPECT_NEAR(rh.areaMm2 / rf.areaMm2, expected, 0.01);
}

TEST(Extract, CropBoxKeepsOnlyWhatIsInside) {
    const core::Volume v = core::makePhantom("sphere", {.size = 32});
    const core::SphereFacts s = core::spherePhantomFacts(v.geometry());
    ExtractOptions o = test::at(0.5);
    const glm::dvec3 lo = s.centre - glm::dvec3(100.0),
                     hi = s.centre + glm::dvec3(100.0, 100.0, 0.0);
    o.keep = core::boxHalfSpaces(lo, hi);
    const Extraction ex = extractIsosurface(v, o);
    ASSERT_GT(ex.mesh.n_faces(), 0u);
    for (const auto vh : ex.mesh.vertices())
        ASSERT_LE(toGlm(ex.mesh.point(vh)).z, s.centre.z + 1e-9);
}

/// An int16 ball whose values rise by `step` per voxel through the isovalue 300, in steps of half
/// a voxel so that a whole shell of voxels is exactly 300. Centred far from index 0 (coordinates ≈ 30, where
/// a float's resolution is ≈ 2e-6 voxel): a steep step (1000: bone against soft tissue) puts a
/// barely moved isovalue's vertices within rounding of the grid points.
core::Volume integerBall(double step) {
    core::Geometry g;
    g.dims = {40, 40, 40};
    core::Volume v(g, core::VoxelType::Int16);
    auto* d = v.dataAs<std::int16_t>();
    const glm::dvec3 c(30.5, 29.0, 30.25);
    for (int k = 0; k < 40; ++k)
        for (int j = 0; j < 40; ++j)
            for (int i = 0; i < 40; ++i) {
                const double r = glm::length(glm::dvec3(i, j, k) - c);
                // Distance quantised to half voxels: a shell of voxels sits exactly at 300.
                const double q = std::round(2.0 * (7.0 - r)) / 2.0;
                d[v.linearIndex(i, j, k)] =
                    std::int16_t(std::clamp(std::lround(300 + step * q), -1000L, 3000L));
            }
    return v;
}

TEST(Extract, IntegerIsovalueOnIntegerDataIsHandled) {
    for (const double step : {10.0, 1000.0}) {
        SCOPED_TRACE(step);
        const core::Volume v = integerBall(step);
        std::size_t atIso = 0;
        for (std::size_t i = 0; i < v.voxelCount(); ++i)
            atIso += v.dataAs<std::int16_t>()[i] == 300;
        ASSERT_GT(atIso, 20u);
        const Extraction ex = extractIsosurface(v, test::at(300.0));
        EXPECT_TRUE(ex.stats.nudged);
        EXPECT_EQ(ex.stats.storedIsovalue, 300.0 - kIntegerIsoNudge);
        EXPECT_EQ(ex.stats.rejectedFaces, 0u);
        const MeshReport r = reportMesh(ex.mesh, true);
        EXPECT_TRUE(r.closed);
        EXPECT_EQ(r.nonManifoldVertices, 0u);
        EXPECT_EQ(r.selfIntersections, 0);
        // No zero-area triangles: voxels at the isovalue are inside, never on the surface.
        for (const auto fh : ex.mesh.faces()) ASSERT_GT(ex.mesh.calc_face_area(fh), 1e-9);
        // Half-integer isovalues are used as given.
        EXPECT_FALSE(extractIsosurface(v, test::at(300.5)).stats.nudged);
    }
}

TEST(Extract, IsovalueOutsideTheRangeAndFlatVolumesAreInputErrors) {
    const core::Volume v = core::makePhantom("sphere", {.size = 16});
    try {
        extractIsosurface(v, test::at(1.5));
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "isovalue");
        EXPECT_NE(std::string(e.what()).find("outside the data range [0, 1]"), std::string::npos)
            << e.what();
    }
    EXPECT_THROW(extractIsosurface(v, test::at(1.0)), InputError);  // the max: no surface
    core::Geometry g;
    g.dims = {8, 8, 8};
    const core::Volume flat(g, core::VoxelType::Int16);
    try {
        extractIsosurface(flat, test::at(0.0));
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "volume");
        EXPECT_NE(std::string(e.what()).find("flat"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace voxlight::iso
