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

// A noisy isovalue on a large volume asked for tens of GB without a word (a 256³ noise volume: 53 M
// triangles, 9.5 GB, 70–400 s; 512³ would need ≈ 75 GB). The estimate counts the voxel edges the
// surface crosses — one mesh vertex each, so exactly the vertex count without cuts — and refuses
// before extracting; a crop box counts only what it keeps.
TEST(Extract, AnIsosurfaceOverTheMemoryBudgetIsRefusedBeforeExtraction) {
    core::Geometry g;
    g.dims = {24, 20, 16};
    const core::Volume v = test::fieldVolume(g, [](const glm::dvec3& p) {
        const auto h = std::uint32_t(p.x * 73856093.0) ^ std::uint32_t(p.y * 19349663.0) ^
                       std::uint32_t(p.z * 83492791.0);
        return double((h * 2654435761u) >> 8) / double(1u << 24);
    });
    ExtractOptions o = test::at(0.5);
    const std::size_t vertices = extractIsosurface(v, o).mesh.n_vertices();
    ASSERT_GT(vertices, 1000u);
    auto refusal = [&](const ExtractOptions& opts) {
        try {
            extractIsosurface(v, opts);
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), "memory");
            return std::string(e.what());
        }
        return std::string("no error");
    };
    o.maxMemoryMiB = 1e-6;
    EXPECT_NE(refusal(o).find(std::to_string(vertices) + " voxel edges"), std::string::npos)
        << refusal(o);
    // Kept: half of the volume along x — about half the edges.
    o.keep = core::boxHalfSpaces({-1, -1, -1}, {11.5, 100, 100});
    const std::string half = refusal(o);
    const std::size_t at = half.find(" crosses ");
    ASSERT_NE(at, std::string::npos) << half;
    const double kept = std::stod(half.substr(at + 9));
    EXPECT_NEAR(kept / double(vertices), 0.5, 0.1);
    // Within the budget: extracted.
    o.keep.clear();
    o.maxMemoryMiB = 1024;
    EXPECT_EQ(extractIsosurface(v, o).mesh.n_vertices(), vertices);
}

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

TEST(Extract, APlaneAHairOffAVoxelPlaneCutsNoSlivers) {
    // A plane 1e-7 mm off the voxel-centre plane x = 18 (an OBJ's 6 decimals of it) cut every
    // triangle with a vertex there into slivers whose new points rounded onto the old ones in
    // float32: 803 zero-area faces on the abdominal CT, 1005 and 314 duplicate vertices capped
    // (probe). Within the snap the plane passes through those vertices instead.
    const core::Volume v = core::makePhantom("sphere", {.size = 32});
    const double x18 = v.geometry().indexToWorld({18.0, 0.0, 0.0}).x;
    for (const double off : {1e-7, -1e-7, 0.0})
        for (const bool cap : {false, true}) {
            ExtractOptions o = test::at(0.5);
            o.keep.push_back({{x18 + off, 0.0, 0.0}, {1.0, 0.0, 0.0}});
            o.cap = cap;
            const Extraction ex = extractIsosurface(v, o);
            ASSERT_GT(ex.mesh.n_faces(), 100u);
            std::size_t flat = 0;
            for (const auto fh : ex.mesh.faces()) {
                std::array<glm::dvec3, 3> t;
                int k = 0;
                for (const auto vh : ex.mesh.fv_range(fh))
                    t[k++] = glm::dvec3(glm::vec3(toGlm(ex.mesh.point(vh))));  // as written
                flat += glm::length(glm::cross(t[1] - t[0], t[2] - t[0])) == 0.0;
            }
            EXPECT_EQ(flat, 0u) << "off " << off << (cap ? " capped" : " open");
            // The vertices the cut passes through were moved onto the (possibly nudged) plane:
            // nothing is left a hair off it.
            for (const auto vh : ex.mesh.vertices()) {
                const double d = ex.planes.at(0).distance(toGlm(ex.mesh.point(vh)));
                if (std::abs(d) < 1e-5) ASSERT_LT(std::abs(d), 1e-9) << "off " << off << cap;
            }
            const MeshReport r = reportMesh(ex.mesh, true);
            EXPECT_EQ(r.selfIntersections, 0) << "off " << off << (cap ? " capped" : " open");
            if (cap) {
                EXPECT_TRUE(r.closed) << "off " << off;
                EXPECT_EQ(r.nonManifoldVertices, 0u) << "off " << off;
            }
        }
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

/// Capped cuts against the analytic solid: a capped surface encloses the kept part of the solid,
/// whose volume the faceting (−0.12 % at 22 voxels per radius, above) and the cap's flat fill (exact
/// on the plane) change by well under this; 1.5 % allows the coarser 32³ grid used here (≈ 11
/// voxels per radius: −0.5 % measured for the whole sphere).
constexpr double kCapVolumeTol = 0.015;

/// Closed, manifold, wound outward (positive volume), nothing left open or failed.
void expectWatertight(const Extraction& ex) {
    EXPECT_EQ(ex.stats.capOpenEdges, 0u);
    EXPECT_EQ(ex.stats.capFailures, 0u);
    EXPECT_GT(ex.stats.capTriangles, 0u);
    EXPECT_EQ(ex.stats.rejectedFaces, 0u);
    const MeshReport r = reportMesh(ex.mesh, true);
    EXPECT_TRUE(r.closed) << r;
    EXPECT_EQ(r.boundaryEdges, 0u) << r;
    EXPECT_EQ(r.nonManifoldVertices, 0u) << r;
    EXPECT_EQ(r.selfIntersections, 0) << r;
    EXPECT_GT(r.volumeMm3, 0.0) << r;
}

TEST(Extract, ACappedCutIsWatertightAndEnclosesTheKeptPartOfTheSolid) {
    const core::Volume v = core::makePhantom("sphere", {.size = 32});
    const core::SphereFacts s = core::spherePhantomFacts(v.geometry());
    ExtractOptions o = test::at(0.5);
    const double off = 0.3;  // off the grid's symmetry plane
    o.keep.push_back({s.centre + glm::dvec3(off, 0, 0), {1.0, 0.0, 0.0}});
    o.cap = true;
    const Extraction ex = extractIsosurface(v, o);
    expectWatertight(ex);
    const double R = s.radius, h = R - off;
    const double cap = std::numbers::pi * h * h * (3.0 * R - h) / 3.0;  // spherical cap's volume
    EXPECT_NEAR(reportMesh(ex.mesh, false).volumeMm3 / cap, 1.0, kCapVolumeTol);
    // The cap lies on the plane; its area is the disk's, π(R² − off²), to the rim's faceting.
    double capArea = 0.0;
    for (const auto fh : ex.mesh.faces()) {
        bool onPlane = true;
        for (const auto vh : ex.mesh.fv_range(fh))
            onPlane = onPlane && std::abs(toGlm(ex.mesh.point(vh)).x - (s.centre.x + off)) < 1e-9;
        if (onPlane) capArea += ex.mesh.calc_face_area(fh);
    }
    EXPECT_NEAR(capArea / (std::numbers::pi * (R * R - off * off)), 1.0, kCapVolumeTol);
    // Shading: a rim vertex's normal is the bisector of the surface's (here ⟂ the cap's, within
    // the faceting) and the cap's outward −x, so no side of the crease is lit edge-on.
    for (const auto vh : ex.mesh.vertices()) {
        if (std::abs(toGlm(ex.mesh.point(vh)).x - (s.centre.x + off)) > 1e-9) continue;
        EXPECT_NEAR(glm::dot(toGlm(ex.mesh.normal(vh)), glm::dvec3(-1, 0, 0)), std::sqrt(0.5), 0.1);
    }
    // Without the cap: the same surface, open.
    o.cap = false;
    EXPECT_GT(reportMesh(extractIsosurface(v, o).mesh, false).boundaryEdges, 0u);
}

TEST(Extract, ACappedCutIsWoundOutwardUnderAMirroringDirection) {
    // det(direction) = −1 reverses VTK's winding in world space: the cap must follow the surface.
    const core::Geometry g = obliqueGeometry();
    const Ball b{g.indexToWorld({17.5, 14.0, 19.0}), 11.0};
    ExtractOptions o = test::at(0.0);
    const glm::dvec3 n = glm::normalize(glm::dvec3(1, 2, 3)), shift(0.2, -0.1, 0.3);
    o.keep.push_back({b.centre + shift, n});
    o.cap = true;
    const Extraction ex = extractIsosurface(test::ballsVolume(g, {b}), o);
    expectWatertight(ex);
    const double R = b.radius, h = R - glm::dot(shift, n);
    const double cap = std::numbers::pi * h * h * (3.0 * R - h) / 3.0;
    EXPECT_NEAR(reportMesh(ex.mesh, false).volumeMm3 / cap, 1.0, kCapVolumeTol);
}

TEST(Extract, CappedCropBoxCornerIsWatertight) {
    // Three planes through (near) the centre: an eighth of the ball, its three caps meeting along
    // the box's edges (each cap is cut by the planes after it).
    const core::Volume v = core::makePhantom("sphere", {.size = 32});
    const core::SphereFacts s = core::spherePhantomFacts(v.geometry());
    ExtractOptions o = test::at(0.5);
    const glm::dvec3 lo = s.centre + glm::dvec3(0.3, 0.2, 0.1);
    o.keep = core::boxHalfSpaces(lo, lo + glm::dvec3(100.0));
    o.cap = true;
    const Extraction ex = extractIsosurface(v, o);
    expectWatertight(ex);
    // An eighth of the ball less the slivers the offsets cut away: between the octant with the
    // offsets and the whole octant.
    const double eighth = std::numbers::pi * std::pow(s.radius, 3) / 6.0;
    const double vol = reportMesh(ex.mesh, false).volumeMm3;
    EXPECT_LT(vol, eighth * (1.0 + kCapVolumeTol));
    EXPECT_GT(vol, eighth * (1.0 - 3.0 * 0.3 / s.radius * 1.5) * (1.0 - kCapVolumeTol));
}

TEST(Extract, ACappedCutThroughAShellCapsTheRingNotTheHollow) {
    // A hollow ball (radii 12 and 7 mm): the cut's contours are two circles, the inner one a hole.
    core::Geometry g;
    g.dims = {40, 40, 40};
    const glm::dvec3 c(19.6, 19.3, 19.45);
    const double R1 = 12.0, R2 = 7.0;
    const core::Volume v = test::fieldVolume(g, [&](const glm::dvec3& p) {
        const double r = glm::length(p - c);
        return std::min(R1 - r, r - R2);
    });
    ExtractOptions o = test::at(0.0);
    o.keep.push_back({c, {0.0, 0.0, -1.0}});  // keep the lower half
    o.cap = true;
    const Extraction ex = extractIsosurface(v, o);
    expectWatertight(ex);
    const double half = 2.0 / 3.0 * std::numbers::pi * (R1 * R1 * R1 - R2 * R2 * R2);
    EXPECT_NEAR(reportMesh(ex.mesh, false).volumeMm3 / half, 1.0, kCapVolumeTol);
    // One solid piece: outer and inner hemispheres joined by the ring.
    EXPECT_EQ(reportMesh(ex.mesh, false).components, 1u);
}

TEST(Extract, ACutThroughAnOpenSurfaceLeavesWhatCannotCloseOpen) {
    // A ball cut off by the volume's border (flying edges leaves that side open): the plane's cut
    // is an arc, not a loop — counted, not capped, and nothing breaks.
    core::Geometry g;
    g.dims = {30, 30, 30};
    const core::Volume v = test::ballsVolume(g, {{{14.6, 14.3, 2.2}, 10.0}});
    ExtractOptions o = test::at(0.0);
    o.keep.push_back({{14.6, 14.3, 5.0}, {1.0, 0.0, 0.0}});
    o.cap = true;
    const Extraction ex = extractIsosurface(v, o);
    EXPECT_GT(ex.stats.capOpenEdges, 0u);
    EXPECT_EQ(ex.stats.rejectedFaces, 0u);
    EXPECT_EQ(reportMesh(ex.mesh, false).nonManifoldVertices, 0u);
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
