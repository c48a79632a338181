// SPDX-License-Identifier: MIT
// The illumination lattice (iso/lattice.h) against closed forms: a convex surface under a uniform
// sky, the floor of a well (a cone of sky), energy bounds with interreflections, lazy = full, any
// thread count, SH transfer re-dotting.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>

#include "core/error.h"
#include "iso/lattice.h"
#include "iso_test_util.h"
#include "lights/environment_light.h"

namespace voxlight::iso {
namespace {

using test::Ball;
using test::ballsVolume;

constexpr double kPi = std::numbers::pi;

/// A uniform sky of radiance L (an equirect map of one value; 128 × 64 pixels, so that its SH
/// projection — pixel-centre values × exact solid angles — leaves ≤ 0.05 % in bands 2 and 4, where a
/// 16 × 8 map leaves 1.5 %).
std::shared_ptr<const lights::Light> sky(float L) {
    core::ImageRGBA img(128, 64);
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            float* p = img.at(x, y);
            p[0] = p[1] = p[2] = L;
            p[3] = 1.f;
        }
    return std::make_shared<lights::EnvironmentLight>(img, lights::EnvironmentOptions{}, "sky");
}

/// A TF whose albedo is `a` at every value (the lattice reads only the albedo).
optics::TransferFunction albedoTf(float a, float lo, float hi) {
    optics::TfPoint p0, p1;
    p0.value = lo, p1.value = hi;
    p0.color = p1.color = glm::vec3(a);
    p0.extinction = p1.extinction = 1.f;
    return optics::TransferFunction({p0, p1}, optics::Window{0.5f * (lo + hi), hi - lo});
}

core::Geometry cube(int n, double spacing = 1.0) {
    core::Geometry g;
    g.dims = glm::ivec3(n);
    g.spacing = glm::dvec3(spacing);
    g.origin = glm::dvec3(-0.5 * (n - 1) * spacing);
    return g;
}

std::shared_ptr<const core::Volume> share(core::Volume v) {
    return std::make_shared<const core::Volume>(std::move(v));
}

/// A plate whose top is z = D with a round well of radius R down to a floor at z = 0, solid below
/// the floor: value = −(signed distance of the CSG union {z ≤ 0} ∪ ({z ≤ D} ∩ {r ≥ R})), so the
/// 0-level set is the shape and the value rises into the solid.
core::Volume wellVolume(const core::Geometry& g, double R, double D) {
    return test::fieldVolume(
        g,
        [&](const glm::dvec3& p) {
            return -std::min(p.z, std::max(p.z - D, R - std::hypot(p.x, p.y)));
        },
        "well");
}

LatticeOptions opts(int samples, int bounces, LatticeMode mode = LatticeMode::Irradiance) {
    LatticeOptions o;
    o.samples = samples;
    o.bounces = bounces;
    o.mode = mode;
    return o;
}

// Relative error allowed for a convex surface under a uniform sky, where every path escapes in the
// continuous model: cosine-sampled directions that graze the surface can still meet the trilinear
// isosurface's voxel-scale bumps (its normal is the B-spline smoothed one); measured 0 % on the
// ball of radius 10 voxels — the bound leaves room for such grazing hits.
constexpr double kConvexTolerance = 0.005;

TEST(Lattice, AConvexSurfaceUnderAUniformSkyGetsPiL) {
    const float L = 0.8f;
    const core::Geometry g = cube(32);
    IlluminationLattice lat(share(ballsVolume(g, {Ball{{0, 0, 0}, 10.0}})), albedoTf(0.f, -20, 20),
                            {sky(L)}, opts(64, 2));
    const LatticeStats st = lat.requireIsosurface(0.0);
    ASSERT_GT(st.texelsComputed, 1000u);
    EXPECT_EQ(st.texelsReused, 0u);
    EXPECT_LT(st.texelsNeeded, st.texelsFull / 4);  // only the surface's texels
    int checked = 0;
    for (int k = 0; k < g.dims.z; ++k)
        for (int j = 0; j < g.dims.y; ++j)
            for (int i = 0; i < g.dims.x; ++i) {
                if (!lat.computed({i, j, k})) continue;
                const glm::vec3 e = lat.texelIrradiance({i, j, k});
                ASSERT_NEAR(e.x, kPi * L, kConvexTolerance * kPi * L) << i << " " << j << " " << k;
                ++checked;
            }
    EXPECT_EQ(std::uint64_t(checked), st.texelsNeeded);
}

// The floor's centre of a well of radius R and depth D sees the sky through a cone of half-angle
// θ = atan(R/D): E = π·L·sin²θ (albedo 0: nothing else lights it). Tolerance: 3 standard errors
// of the Bernoulli estimate plus the rim's discretisation (the trilinear level set of the wall
// lies within ≈ h²/(8R) of the cylinder, and the rim's edge is rounded within one voxel:
// d(sin²θ)/dR = sin 2θ · D/(R² + D²) → ≤ 2 % of E per half voxel at R = D = 16).
TEST(Lattice, TheFloorOfAWellSeesItsConeOfSky) {
    const double R = 16, D = 16;
    const float L = 1.f;
    core::Geometry g;
    g.dims = {72, 72, 40};
    g.origin = {-36.0, -36.0, -4.0};  // voxel (36, 36, 4) is world (0, 0, 0), the floor's centre
    const int samples = 20000;
    IlluminationLattice lat(share(wellVolume(g, R, D)), albedoTf(0.f, -40, 40), {sky(L)},
                            opts(samples, 0));
    const glm::ivec3 floor(36, 36, 4);
    const LatticeStats st = lat.require(std::vector<glm::dvec3>{glm::dvec3(0.0)});
    EXPECT_EQ(st.texelsNeeded,
              1u);  // a point exactly on a texel needs only it (the others weigh 0)
    ASSERT_TRUE(lat.computed(floor));
    const double sin2 = std::pow(std::sin(std::atan(R / D)), 2.0);
    const double expected = kPi * L * sin2;
    const double se = kPi * L * std::sqrt(sin2 * (1 - sin2) / samples);
    const double discretisation = 0.02 * expected;
    EXPECT_NEAR(lat.texelIrradiance(floor).x, expected, 3 * se + discretisation);
}

// Radiance never exceeds the sky's anywhere when albedo ≤ 1, so E ≤ π·L for every texel whatever
// the bounces (the furnace limit); and each bounce adds light where the surface sees itself.
TEST(Lattice, InterreflectionsAddLightButNeverExceedTheFurnaceLimit) {
    const float L = 1.f;
    core::Geometry g;
    g.dims = {40, 40, 28};
    g.origin = {-20.0, -20.0, -4.0};
    auto vol = share(wellVolume(g, 8, 16));
    const std::vector<glm::dvec3> floorPoint{glm::dvec3(0.0)};
    double previous = 0.0;
    for (const int bounces : {0, 1, 4}) {
        IlluminationLattice lat(vol, albedoTf(1.f, -40, 40), {sky(L)}, opts(4000, bounces));
        lat.require(floorPoint);
        const double e = lat.irradiance(glm::dvec3(0.0)).x;
        EXPECT_GT(e, previous * 1.05) << bounces << " bounces";
        EXPECT_LE(e, kPi * L) << bounces << " bounces";
        previous = e;
        // Every texel of the whole surface stays under the limit (few paths: the bound holds for
        // every path, not only on average).
        IlluminationLattice whole(vol, albedoTf(1.f, -40, 40), {sky(L)}, opts(4, bounces));
        whole.requireIsosurface(0.0);
        for (int k = 0; k < g.dims.z; ++k)
            for (int j = 0; j < g.dims.y; ++j)
                for (int i = 0; i < g.dims.x; ++i)
                    if (whole.computed({i, j, k})) {
                        ASSERT_LE(whole.texelIrradiance({i, j, k}).x, kPi * L * (1 + 1e-5));
                    }
    }
}

// Lazy = full, bit for bit, and the thread count changes nothing: every texel's random numbers
// depend only on its index, its sample and the seed.
TEST(Lattice, LazyTexelsEqualAFreshComputationForAnyThreadCount) {
    const core::Geometry g = cube(24);
    auto vol = share(ballsVolume(g, {Ball{{-2, 0, 0}, 6.0}, Ball{{4, 1, 0}, 5.0}}));
    auto light =
        std::make_shared<lights::DirectionalLight>(glm::vec3(2.f), glm::vec3(0.3f, 0.5f, 1.f));
    LatticeOptions a = opts(16, 1);
    a.threads = 2;
    IlluminationLattice lazy(vol, albedoTf(0.7f, -20, 20), {sky(0.5f), light}, a);
    const LatticeStats s1 = lazy.requireIsosurface(0.0);
    const LatticeStats s2 = lazy.requireIsosurface(0.5);  // half a voxel further out
    EXPECT_GT(s2.texelsReused, s2.texelsNeeded / 2) << "a small isovalue step reuses most texels";
    EXPECT_EQ(s2.texelsComputed + s2.texelsReused, s2.texelsNeeded);
    EXPECT_EQ(s2.texelsStored, s1.texelsComputed + s2.texelsComputed);

    LatticeOptions b = a;
    b.threads = 1;
    IlluminationLattice fresh(vol, albedoTf(0.7f, -20, 20), {sky(0.5f), light}, b);
    fresh.requireIsosurface(0.5);
    int compared = 0;
    for (int k = 0; k < 24; ++k)
        for (int j = 0; j < 24; ++j)
            for (int i = 0; i < 24; ++i)
                if (fresh.computed({i, j, k})) {
                    ASSERT_TRUE(lazy.computed({i, j, k}));
                    const glm::vec3 x = lazy.texelIrradiance({i, j, k}),
                                    y = fresh.texelIrradiance({i, j, k});
                    ASSERT_EQ(x, y) << i << " " << j << " " << k;
                    ++compared;
                }
    EXPECT_GT(compared, 500);
}

// Sharp edges (CT-like: values step across one voxel): Wyman's texels on their own isosurfaces
// lie on plateaus and ramps that are not the surface being shaded, and their blend is far off
// per-point tracing; texels moved onto that surface (TexelPlacement::OnSurface) agree with it up
// to the irradiance's own variation over a voxel and the Monte-Carlo noise. Scene: two balls over a
// floor, a directional light and a sky, 1 bounce; 150 points of the surface (mesh vertices),
// reference 1,024 paths per point, lattices 256 paths per texel (all random numbers fixed: the
// figures repeat exactly). Measured: on-surface NRMS 0.0116, own isosurfaces 0.0292; bound
// kSharpSurfaceNrms on the first, and the second at least twice it. (On the torso phantom's bone
// the gap is larger — README, bench_lattice.)
TEST(Lattice, OnSurfaceTexelsFollowPerPointTracingOnSharpEdgedData) {
    core::Geometry g;
    g.dims = {40, 40, 28};
    g.origin = {-20.0, -20.0, -4.0};
    // Value 1 in the solid, 0 outside, a linear ramp across one voxel at the surface.
    core::Volume v = test::fieldVolume(g, [](const glm::dvec3& p) {
        const double d = std::min({p.z, glm::length(p - glm::dvec3(-4, 0, 10)) - 6.0,
                                   glm::length(p - glm::dvec3(7, 3, 8)) - 4.0});
        return std::clamp(0.5 - d, 0.0, 1.0);
    });
    auto vol = share(std::move(v));
    auto light =
        std::make_shared<lights::DirectionalLight>(glm::vec3(2.f), glm::vec3(0.4f, -0.3f, 1.f));
    const std::vector<std::shared_ptr<const lights::Light>> ls = {sky(0.3f), light};
    const auto tf = albedoTf(0.6f, 0.f, 1.f);
    const double iso = 0.5;
    const Extraction ex = extractIsosurface(*vol, test::at(iso));
    std::vector<glm::dvec3> pts;
    const std::size_t nv = ex.mesh.n_vertices();
    for (std::size_t i = 0; i < 150; ++i)
        pts.push_back(test::toGlm(ex.mesh.point(Mesh::VertexHandle(int(i * 7919 % nv)))));
    IlluminationLattice refLat(vol, tf, ls, opts(1, 1));
    std::vector<glm::vec3> ref;
    for (std::size_t i = 0; i < pts.size(); ++i)
        ref.push_back(refLat.pointIrradiance(pts[i], iso, 1024, 5000 + i));
    auto nrms = [&](IlluminationLattice& lat) {
        lat.require(pts, iso);
        double se = 0.0, sr = 0.0;
        for (std::size_t i = 0; i < pts.size(); ++i) {
            const double e = lat.irradiance(pts[i], iso).x, r = ref[i].x;
            se += (e - r) * (e - r);
            sr += r;
        }
        return std::sqrt(se / double(pts.size())) / (sr / double(pts.size()));
    };
    LatticeOptions on = opts(256, 1);
    on.placement = TexelPlacement::OnSurface;
    on.surfaceIso = iso;
    IlluminationLattice onSurface(vol, tf, ls, on);
    IlluminationLattice own(vol, tf, ls, opts(256, 1));
    const double eOn = nrms(onSurface), eOwn = nrms(own);
    constexpr double kSharpSurfaceNrms = 0.03;
    EXPECT_LT(eOn, kSharpSurfaceNrms) << "own-isosurface texels: " << eOwn;
    EXPECT_GT(eOwn, 2.0 * eOn) << "on-surface texels: " << eOn;
    // An isovalue outside the data cannot place texels.
    LatticeOptions bad = on;
    bad.surfaceIso = 2.0;
    try {
        IlluminationLattice l(vol, tf, ls, bad);
        ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "isovalue");
    }
}

// Skip distances (Tracer::skipFor) only jump over cells that cannot hold a crossing: irradiance
// traced with them equals irradiance traced with the 8³ bricks alone, path for path (the same
// random numbers; crossings agree to float rounding of where a cell is entered). The scene hides
// thin rods (radius 0.7 voxel) among two balls over a floor, so a distance one cell too large
// would let paths and shadow rays through them and change the sums.
namespace {
/// Thin rods, two balls and a floor: values 0…1 over a one-voxel ramp at each surface.
std::shared_ptr<const core::Volume> rodsAndBalls() {
    core::Geometry g;
    g.dims = {44, 40, 30};
    g.origin = {-22.0, -20.0, -4.0};
    return share(test::fieldVolume(g, [](const glm::dvec3& p) {
        double d = std::min({p.z, glm::length(p - glm::dvec3(-6, 0, 10)) - 6.0,
                             glm::length(p - glm::dvec3(8, 3, 7)) - 3.5});
        for (int r = 0; r < 5; ++r)  // rods along y at several heights and x
            d = std::min(d, std::hypot(p.x - (-15.0 + 7.3 * r), p.z - (3.0 + 4.1 * r)) - 0.7);
        return std::clamp(0.5 - d, 0.0, 1.0);
    }));
}
}  // namespace

TEST(Lattice, SkipDistancesChangeNoCrossing) {
    auto vol = rodsAndBalls();
    auto light =
        std::make_shared<lights::DirectionalLight>(glm::vec3(2.f), glm::vec3(0.5f, -0.2f, 1.f));
    const std::vector<std::shared_ptr<const lights::Light>> ls = {sky(0.3f), light};
    const auto tf = albedoTf(0.6f, 0.f, 1.f);
    const double iso = 0.5;
    const Extraction ex = extractIsosurface(*vol, test::at(iso));
    LatticeOptions withSkip = opts(64, 2), bricksOnly = opts(64, 2);
    bricksOnly.skipDistances = false;
    IlluminationLattice a(vol, tf, ls, withSkip), b(vol, tf, ls, bricksOnly);
    const std::size_t nv = ex.mesh.n_vertices();
    double maxDiff = 0.0, maxE = 0.0;
    for (std::size_t i = 0; i < 200; ++i) {
        const glm::dvec3 p = test::toGlm(ex.mesh.point(Mesh::VertexHandle(int(i * 7919 % nv))));
        const glm::vec3 ea = a.pointIrradiance(p, iso, 64, i),
                        eb = b.pointIrradiance(p, iso, 64, i);
        const glm::vec3 da = a.directIrradiance(p, iso, true),
                        db = b.directIrradiance(p, iso, true);
        const glm::vec3 va = a.vicinityIrradiance(p, iso, 6.0, 32, i),
                        vb = b.vicinityIrradiance(p, iso, 6.0, 32, i);
        maxDiff = std::max({maxDiff, double(glm::length(ea - eb)), double(glm::length(da - db)),
                            double(glm::length(va - vb))});
        maxE = std::max(maxE, double(glm::length(eb)));
    }
    // Float rounding of the crossings only (a changed path would differ by ≥ 1e-3 of E).
    constexpr double kRounding = 1e-6;
    EXPECT_LE(maxDiff, kRounding * maxE);
    EXPECT_GT(maxE, 0.5);
    // The comparison means something only if one side did skip: one field, for this isovalue.
    EXPECT_EQ(a.skipFieldCount(), 1);
    EXPECT_EQ(b.skipFieldCount(), 0);
}

// An isovalue slider: every isovalue gets its skip distances (a third replaces the least recently
// used of the two kept, it does not fall back to the bricks alone), shadows stay those of the
// bricks, and the tracer's reported memory counts the fields it holds.
TEST(Lattice, AThirdIsovalueReplacesTheLeastRecentlyUsedSkipField) {
    auto vol = rodsAndBalls();
    auto light =
        std::make_shared<lights::DirectionalLight>(glm::vec3(2.f), glm::vec3(0.5f, -0.2f, 1.f));
    const auto tf = albedoTf(0.6f, 0.f, 1.f);
    LatticeOptions bricksOnly = opts(64, 0);
    bricksOnly.skipDistances = false;
    IlluminationLattice a(vol, tf, {light}, opts(64, 0)), b(vol, tf, {light}, bricksOnly);
    const double bricksMiB = b.tracerMiB();
    EXPECT_GE(bricksMiB, 4.0 * double(vol->voxelCount()) / (1024.0 * 1024.0));  // the float copy
    // Each step: the isovalue and how many fields have been built after it (0.3, 0.5, 0.7 fill
    // and replace; 0.5 is then the most recent but one, so 0.3 replaces 0.7, not 0.5).
    const std::pair<double, int> steps[] = {{0.3, 1}, {0.5, 2}, {0.7, 3},
                                            {0.5, 3}, {0.3, 4}, {0.5, 4}};
    for (const auto& [iso, built] : steps) {
        const Extraction ex = extractIsosurface(*vol, test::at(iso));
        const std::size_t nv = ex.mesh.n_vertices();
        double maxDiff = 0.0, maxE = 0.0;
        for (std::size_t i = 0; i < 100; ++i) {
            const glm::dvec3 p = test::toGlm(ex.mesh.point(Mesh::VertexHandle(int(i * 7919 % nv))));
            const glm::vec3 da = a.directIrradiance(p, iso, true),
                            db = b.directIrradiance(p, iso, true);
            maxDiff = std::max(maxDiff, double(glm::length(da - db)));
            maxE = std::max(maxE, double(glm::length(db)));
        }
        constexpr double kRounding = 1e-6;  // as in SkipDistancesChangeNoCrossing
        EXPECT_LE(maxDiff, kRounding * maxE) << "isovalue " << iso;
        EXPECT_GT(maxE, 0.5);
        EXPECT_EQ(a.skipFieldsBuilt(), std::uint64_t(built)) << "after isovalue " << iso;
        EXPECT_LE(a.skipFieldCount(), 2);
    }
    EXPECT_EQ(b.skipFieldsBuilt(), 0u);
    // Two fields of one byte per cell (the 4³ tiles pad 43×39×29 cells to 44×40×32) and their
    // tile distances.
    const double fieldsMiB = 2.0 * (44 * 40 * 32 + 11 * 10 * 8) / (1024.0 * 1024.0);
    EXPECT_NEAR(a.tracerMiB() - bricksMiB, fieldsMiB, 1e-9);
}

// Shadows: a ball between a directional light and a floor darkens the floor below it (E = 0 in
// the umbra with albedo 0 and no sky) and not beside it (E = E_l cos θ).
TEST(Lattice, ADirectionalLightCastsAShadow) {
    core::Geometry g;
    g.dims = {48, 48, 32};
    g.origin = {-24.0, -24.0, -4.0};
    // A floor (top at z = 0) and a ball of radius 6 above it.
    core::Volume v = test::fieldVolume(g, [](const glm::dvec3& p) {
        return -std::min(p.z, glm::length(p - glm::dvec3(0, 0, 14)) - 6.0);
    });
    const float E = 2.f;
    auto light = std::make_shared<lights::DirectionalLight>(glm::vec3(E), glm::vec3(0, 0, 1));
    IlluminationLattice lat(share(std::move(v)), albedoTf(0.f, -40, 40), {light}, opts(4, 0));
    const std::vector<glm::dvec3> pts{{0, 0, 0}, {18, 0, 0}};
    lat.require(pts);
    EXPECT_NEAR(lat.irradiance(pts[0]).x, 0.0, 1e-6);    // under the ball
    EXPECT_NEAR(lat.irradiance(pts[1]).x, E, 1e-3 * E);  // open floor, light straight above
}

TEST(Lattice, TexelsSpanTheVolumeToItsLastVoxelAtEveryResolution) {
    // 64 voxels at 0.5 texels per voxel: texels at 0, 2, …, 62 left voxel 63 to extrapolation
    // (probe: vertices there baked 25 % too bright). Now they span 0…63, as evenly as fits.
    core::Geometry g = cube(64);
    g.dims = {64, 33, 2};
    const auto volume = share(test::fieldVolume(g, [](const glm::dvec3& p) { return -p.z; }));
    auto light = std::make_shared<lights::DirectionalLight>(glm::vec3(1.f), glm::vec3(0, 0, 1));
    for (const double res : {0.5, 1.0, 2.0, 3.0}) {
        SCOPED_TRACE(res);
        LatticeOptions o = opts(1, 0);
        o.resolution = res;
        IlluminationLattice lat(volume, albedoTf(0.f, -40, 40), {light}, o);
        const glm::ivec3 last = lat.dims() - 1;
        const glm::dvec3 end = lat.texelIndexPosition(last);
        for (int a = 0; a < 3; ++a) EXPECT_NEAR(end[a], g.dims[a] - 1, 1e-9) << a;
        for (int a = 0; a < 3; ++a)
            if (g.dims[a] > 1)
                EXPECT_LE(lat.texelIndexPosition(glm::ivec3(1))[a], 1.0 / res + 1e-12) << a;
    }
}

TEST(Lattice, MatterACutRemovesCastsNoShadowAndWhatItKeepsStillDoes) {
    // The floor and ball of the test above, cut by a plane keeping z ≤ h: the bake and the
    // lattice traced the whole volume (probe: the removed ball's shadow kept, 0 where 0.9/π·n·l
    // belonged). At h = 8 the whole ball (z 8…20) is gone; at h = 14 its lower half stays and
    // still shadows the floor below it.
    core::Geometry g;
    g.dims = {48, 48, 32};
    g.origin = {-24.0, -24.0, -4.0};
    const auto volume = share(test::fieldVolume(g, [](const glm::dvec3& p) {
        return -std::min(p.z, glm::length(p - glm::dvec3(0, 0, 14)) - 6.0);
    }));
    const float E = 2.f;
    auto light = std::make_shared<lights::DirectionalLight>(glm::vec3(E), glm::vec3(0, 0, 1));
    const std::vector<glm::dvec3> pts{{0, 0, 0}, {18, 0, 0}};
    for (const double h : {8.0, 14.0}) {
        SCOPED_TRACE(h);
        LatticeOptions o = opts(4, 0);
        o.keep = {core::HalfSpace{{0, 0, h}, {0, 0, -1}}};
        IlluminationLattice lat(volume, albedoTf(0.f, -40, 40), {light}, o);
        const double under = h < 10.0 ? E : 0.0;
        EXPECT_NEAR(lat.directIrradiance(pts[0], 0.0, true).x, under, 1e-3 * E);
        EXPECT_NEAR(lat.directIrradiance(pts[1], 0.0, true).x, E, 1e-3 * E);
        lat.require(pts);
        EXPECT_NEAR(lat.irradiance(pts[0]).x, under, 1e-3 * E);
        EXPECT_NEAR(lat.irradiance(pts[1]).x, E, 1e-3 * E);
    }
    // A ray that enters the kept region inside matter meets the cut face: under a light from
    // below (−z), a point above the cut (z = 17, in the removed half of the ball) looks down into
    // the kept half's cut face at z = 14.
    LatticeOptions o = opts(4, 0);
    o.keep = {core::HalfSpace{{0, 0, 14}, {0, 0, -1}}};
    auto below = std::make_shared<lights::DirectionalLight>(glm::vec3(E), glm::vec3(0, 0, -1));
    IlluminationLattice lat(volume, albedoTf(0.f, -40, 40), {below}, o);
    EXPECT_NEAR(lat.directIrradiance({0, 0, 17}, 0.0, true).x, 0.0, 1e-6);
}

TEST(Lattice, APathLeavingTheBoxBeforeTheKeptRegionMeetsNothing) {
    // A floor (z ≤ 0) and a slab under the volume's top face (z ≥ 20, x ≤ 12); the cut keeps
    // x ≤ 10. From the removed floor at x = 20 a path toward the light (up, slightly −x) leaves
    // the box at x ≈ 17.3, long before it could enter the kept region: it was tested at the border
    // voxel its entry clamped to, (10, 0, 27), inside the slab, and called a cut face (review).
    core::Geometry g;
    g.dims = {48, 48, 32};
    g.origin = {-24.0, -24.0, -4.0};
    const auto volume = share(test::fieldVolume(
        g, [](const glm::dvec3& p) { return std::max(-p.z, std::min(p.z - 20.0, 12.0 - p.x)); }));
    const float E = 2.f;
    const glm::vec3 toLight = glm::normalize(glm::vec3(-0.1f, 0.f, 1.f));
    auto light = std::make_shared<lights::DirectionalLight>(glm::vec3(E), toLight);
    LatticeOptions o = opts(4, 0);
    o.keep = {core::HalfSpace{{10, 0, 0}, {-1, 0, 0}}};
    IlluminationLattice lat(volume, albedoTf(0.f, -40, 40), {light}, o);
    EXPECT_NEAR(lat.directIrradiance({20, 0, 0}, 0.0, true).x, E * toLight.z, 1e-3 * E);
}

// SH transfer: a uniform sky is exact in band 0 (E = π·L on a convex surface, as the irradiance
// lattice); turning a directional light re-dots without tracing and equals a lattice computed
// for the turned light from the start.
TEST(Lattice, ShTransferRedotsWhenTheLightTurns) {
    const core::Geometry g = cube(24);
    auto vol = share(ballsVolume(g, {Ball{{0, 0, 0}, 7.0}}));
    IlluminationLattice skyLit(vol, albedoTf(0.5f, -20, 20), {sky(1.f)},
                               opts(32, 1, LatticeMode::ShTransfer));
    skyLit.requireIsosurface(0.0);
    for (int k = 0; k < 24; ++k)
        for (int j = 0; j < 24; ++j)
            for (int i = 0; i < 24; ++i)
                if (skyLit.computed({i, j, k})) {
                    ASSERT_NEAR(skyLit.texelIrradiance({i, j, k}).x, kPi, kConvexTolerance * kPi);
                }

    auto l1 = std::make_shared<lights::DirectionalLight>(glm::vec3(1.f), glm::vec3(1, 0, 0));
    auto l2 = std::make_shared<lights::DirectionalLight>(glm::vec3(1.f), glm::vec3(0, 1, 1));
    IlluminationLattice turned(vol, albedoTf(0.5f, -20, 20), {l1},
                               opts(32, 1, LatticeMode::ShTransfer));
    const LatticeStats first = turned.requireIsosurface(0.0);
    turned.setLights({l2});
    const LatticeStats again = turned.requireIsosurface(0.0);
    EXPECT_EQ(again.texelsComputed, 0u);
    EXPECT_EQ(again.pathsTraced, 0u);
    IlluminationLattice direct(vol, albedoTf(0.5f, -20, 20), {l2},
                               opts(32, 1, LatticeMode::ShTransfer));
    direct.requireIsosurface(0.0);
    ASSERT_EQ(first.texelsComputed, again.texelsNeeded);
    for (int k = 0; k < 24; ++k)
        for (int j = 0; j < 24; ++j)
            for (int i = 0; i < 24; ++i)
                if (direct.computed({i, j, k})) {
                    ASSERT_EQ(turned.texelIrradiance({i, j, k}), direct.texelIrradiance({i, j, k}));
                }
}

// At a point of the surface at isovalue v, irradiance(p, v) reads only the texels inside it (value
// ≥ v), weights renormalised: the outside texels' own isosurfaces lie in the matter around it.
TEST(Lattice, ASurfacePointReadsTheTexelsInsideItsSurface) {
    const core::Geometry g = cube(16);
    auto light =
        std::make_shared<lights::DirectionalLight>(glm::vec3(1.f), glm::vec3(0.2f, 0.3f, 1.f));
    IlluminationLattice lat(share(ballsVolume(g, {Ball{{0, 0, 0}, 4.3}})), albedoTf(0.5f, -20, 20),
                            {sky(1.f), light}, opts(8, 1));
    const glm::dvec3 p(0.3, 0.4, 4.25);  // near the top of the ball, inside a cell
    lat.require(std::vector<glm::dvec3>{p});
    const glm::dvec3 q = g.worldToIndex(p);
    const glm::ivec3 i0 = glm::ivec3(glm::floor(q));
    const glm::dvec3 f = q - glm::dvec3(i0);
    glm::dvec3 sum(0.0);
    double w = 0.0;
    int inside = 0;
    for (int c = 0; c < 8; ++c) {
        const glm::ivec3 o(c & 1, (c >> 1) & 1, c >> 2);
        const glm::ivec3 t = i0 + o;
        const double wt = (o.x ? f.x : 1 - f.x) * (o.y ? f.y : 1 - f.y) * (o.z ? f.z : 1 - f.z);
        const double value = 4.3 - glm::length(g.indexToWorld(glm::dvec3(t)));
        if (value < 0.0 || lat.plateau(t)) continue;
        sum += wt * glm::dvec3(lat.texelIrradiance(t));
        w += wt;
        ++inside;
    }
    ASSERT_GT(inside, 0);
    ASSERT_LT(inside, 8);
    const glm::vec3 expected(sum / w), got = lat.irradiance(p, 0.0);
    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(got[ch], expected[ch], 1e-5f * expected[ch]);
    EXPECT_NE(got, lat.irradiance(p));  // all eight texels give another value
}

TEST(Lattice, BadOptionsAndLightsNameTheirField) {
    const core::Geometry g = cube(8);
    auto vol = share(ballsVolume(g, {Ball{{0, 0, 0}, 2.0}}));
    const auto tf = albedoTf(0.5f, -5, 5);
    auto field = [&](LatticeOptions o, std::vector<std::shared_ptr<const lights::Light>> ls) {
        try {
            IlluminationLattice lat(vol, tf, std::move(ls), o);
        } catch (const InputError& e) {
            return e.field();
        }
        return std::string("none");
    };
    LatticeOptions o = opts(10, 1);
    o.samples = 0;
    EXPECT_EQ(field(o, {sky(1)}), "samples");
    o = opts(10, 99);
    EXPECT_EQ(field(o, {sky(1)}), "bounces");
    o = opts(10, 1);
    o.resolution = 16;
    EXPECT_EQ(field(o, {sky(1)}), "resolution");
    o.resolution = 0.5 * kMinLatticeResolution;
    EXPECT_EQ(field(o, {sky(1)}), "resolution");
    o = opts(10, 1, LatticeMode::ShTransfer);
    o.shOrder = 6;
    EXPECT_EQ(field(o, {sky(1)}), "sh_order");
    o.shOrder = 3;
    auto point = std::make_shared<lights::PointLight>(glm::vec3(1.f), glm::dvec3(0, 0, 9));
    EXPECT_EQ(field(o, {point}), "mode");
    EXPECT_EQ(field(opts(10, 1), {point}), "none");

    // Flat volume.
    core::Volume flat(g, core::VoxelType::Float32);
    try {
        IlluminationLattice lat(share(std::move(flat)), tf, {sky(1)}, opts(10, 1));
        ADD_FAILURE() << "a flat volume was accepted";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "volume");
    }
    // Over the memory budget: nothing is computed.
    LatticeOptions tiny = opts(10, 1);
    tiny.memoryBudgetMiB = 0.001;
    IlluminationLattice lat(vol, tf, {sky(1)}, tiny);
    try {
        lat.requireIsosurface(0.0);
        ADD_FAILURE() << "the budget was not enforced";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "memory");
        EXPECT_NE(std::string(e.what()).find("budget"), std::string::npos);
    }
    EXPECT_EQ(lat.texelsStored(), 0u);
}

// Matter cut by the volume's box (a bone cut by the scan's field of view, a slab on a face) shows
// a cap in the ray caster, but the isosurface has no point there: the on-surface lattice left
// those texels out and `iso-lattice` painted every cap black. A cap sees its whole hemisphere
// open (every direction leaves the box at once), so under a uniform sky of radiance L its
// irradiance is π·L with no noise at all (albedo 0: no bounce adds to it).
TEST(Lattice, CapsWhereTheBoxCutsTheMatterAreLitAsOpenSurfaces) {
    constexpr double kCapTolerance = 1e-5;  // float texels; every path escapes exactly
    const float L = 0.7f;
    const core::Geometry g = cube(24);  // index 0 … 23 at world −11.5 … 11.5
    // Solid below z = 0 (value 1, a one-voxel ramp to 0 above): the slab fills the box's bottom
    // face and the lower halves of its four side faces.
    auto vol = share(test::fieldVolume(
        g, [](const glm::dvec3& p) { return std::clamp(0.5 - p.z, 0.0, 1.0); }, "slab"));
    LatticeOptions on = opts(64, 1);
    on.placement = TexelPlacement::OnSurface;
    on.surfaceIso = 0.5;
    IlluminationLattice lat(vol, albedoTf(0.f, 0.f, 1.f), {sky(L)}, on);
    const std::vector<glm::dvec3> caps = {{0.0, 0.0, -11.5},   // the bottom face
                                          {3.2, -4.7, -11.5},  // between texels
                                          {11.5, 0.0, -5.0},   // a side face
                                          {-2.0, -11.5, -7.3}};
    lat.require(caps, 0.5);
    for (const glm::dvec3& p : caps)
        EXPECT_NEAR(lat.irradiance(p, 0.5).x, kPi * L, kCapTolerance * kPi * L)
            << p.x << " " << p.y << " " << p.z;
}

// The render's shading modes other than the lattice (paths, Lambert, shadows, vicinity) take the
// hit point itself; on a cap the field's normal is that of the plateau inside the cut (zero, or
// any direction where the matter varies): the face's normal lights it.
TEST(Lattice, CapsAreLitByEveryPointShading) {
    constexpr double kCapTolerance = 1e-6;  // every path and shadow ray escapes: exact sums
    const float L = 0.7f, E = 1.5f;
    const core::Geometry g = cube(24);
    // Solid below z = 0 with a gentle ramp inside (the gradient there points along x, not out of
    // the bottom face): the cap's normal must come from the face.
    auto vol = share(test::fieldVolume(
        g,
        [](const glm::dvec3& p) {
            return p.z < 0.0 ? 1.0 + 0.01 * p.x : std::clamp(0.5 - p.z, 0.0, 1.0);
        },
        "slab"));
    // A light below, 60° off the bottom face's normal (0, 0, −1).
    const glm::vec3 toLight(std::sin(1.0471976f), 0.f, -std::cos(1.0471976f));
    auto below = std::make_shared<lights::DirectionalLight>(glm::vec3(E), toLight);
    IlluminationLattice lit(vol, albedoTf(0.f, 0.f, 1.f), {sky(L)}, opts(64, 1));
    IlluminationLattice direct(vol, albedoTf(0.f, 0.f, 1.f), {below}, opts(64, 1));
    const std::vector<glm::dvec3> caps = {{0.0, 0.0, -11.5}, {3.2, -4.7, -11.5}};
    for (std::size_t i = 0; i < caps.size(); ++i) {
        const glm::dvec3& p = caps[i];
        SCOPED_TRACE(testing::Message() << p.x << " " << p.y << " " << p.z);
        EXPECT_NEAR(lit.pointIrradiance(p, 0.5, 32, i).x, kPi * L, kCapTolerance * kPi * L);
        EXPECT_NEAR(lit.vicinityIrradiance(p, 0.5, 6.0, 32, i).x, kPi * L, kCapTolerance * kPi * L);
        for (const bool shadows : {false, true})
            EXPECT_NEAR(direct.directIrradiance(p, 0.5, shadows).x, 0.5 * E, kCapTolerance * E);
    }
}

// The coarsest lattice (kMinLatticeResolution: texels 2 voxels apart) on a binary-edged sphere (a
// mask): every vertex reads a texel on the surface. At 0.25, which was allowed, 945 of the 8376
// vertices read none and were baked black.
TEST(Lattice, TheCoarsestLatticeReachesTheSurfaceFromEveryTexel) {
    core::Geometry g;
    g.dims = {64, 64, 64};
    auto vol = share(test::fieldVolume(g, [](const glm::dvec3& p) {
        return glm::length(p - glm::dvec3(31.5)) <= 21.0 ? 1.0 : 0.0;
    }));
    Extraction ex = extractIsosurface(*vol, test::at(0.5));
    LatticeOptions o = opts(4, 0);
    o.placement = TexelPlacement::OnSurface;
    o.surfaceIso = 0.5;
    o.resolution = kMinLatticeResolution;
    IlluminationLattice lat(vol, albedoTf(1.f, 0.f, 1.f), {sky(1.f)}, o);
    bakeVertexColours(ex.mesh, lat, 0.5, glm::vec3(1.f), 1.f, BakeSource::Lattice);
    std::size_t black = 0;
    for (const auto v : ex.mesh.vertices()) black += !(ex.mesh.color(v)[0] > 0.f);
    EXPECT_EQ(black, 0u) << "of " << ex.mesh.n_vertices();
}

}  // namespace
}  // namespace voxlight::iso
