// SPDX-License-Identifier: MIT
// Analytic optics: homogeneous slab and sphere of known σt must give T = exp(−σt·L).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "render_test_util.h"

using namespace voxlight;
using namespace voxlight::test;

namespace {
// The bound on transmittance against the closed form.
constexpr double kTransmittanceTol = 1e-3;

struct Case {
    glm::dvec3 spacing;
    float stepVoxels;
    double azimuth, elevation;
};

render::RenderOptions eaOptions(float step) {
    render::RenderOptions o;
    o.mode = render::Mode::EmissionAbsorption;
    o.stepVoxels = step;
    o.earlyTermination = false;  // measure T exactly, however small
    return o;
}
}  // namespace

TEST(ExactOptics, SlabTransmittanceForAnySpacingStepAndAngle) {
    const Case cases[] = {{{1, 1, 1}, 0.5f, 0, 90},      {{1, 1, 1}, 0.25f, 0, 90},
                          {{1, 1, 1}, 1.0f, 30, 70},     {{1, 1, 1}, 3.7f, 200, 55},
                          {{0.3, 0.3, 5}, 0.5f, 0, 90},  {{0.3, 0.3, 5}, 2.0f, 0, 90},
                          {{0.3, 0.3, 5}, 13.f, 0, -90}, {{0.7, 1.3, 0.9}, 0.8f, 45, 60}};
    for (const Case& c : cases) {
        core::PhantomOptions po;
        po.size = 48;
        po.spacing = c.spacing;
        const core::Volume v = core::makePhantom("slab", po);
        const core::SlabFacts f = core::slabPhantomFacts(v.geometry());
        const float sigma = float(0.8 / (f.zMax - f.zMin));  // τ ≈ 0.8 vertically
        const double minExtentXY = 47 * std::min(c.spacing.x, c.spacing.y);
        const render::Camera cam = orthoCamera(v, c.azimuth, c.elevation, 0.2 * minExtentXY, 8);
        const core::ImageRGBA img = renderWith(v, stepTf(sigma), cam, eaOptions(c.stepVoxels));
        const double L = (f.zMax - f.zMin) / std::abs(cam.forward().z);
        const double expected = std::exp(-sigma * L);
        for (int y = 0; y < 8; ++y)
            for (int x = 0; x < 8; ++x)
                ASSERT_NEAR(1.0 - img.at(x, y)[3], expected, kTransmittanceTol)
                    << "spacing " << c.spacing.x << "x" << c.spacing.y << "x" << c.spacing.z
                    << " step " << c.stepVoxels << " view " << c.azimuth << "/" << c.elevation
                    << " pixel " << x << "," << y;
    }
}

TEST(ExactOptics, SphereTransmittanceMatchesChordLength) {
    const Case cases[] = {
        {{1, 1, 1}, 0.5f, 30, 20}, {{1, 1, 1}, 2.5f, 110, -35}, {{0.6, 0.6, 0.6}, 1.0f, 0, 0}};
    for (const Case& c : cases) {
        core::PhantomOptions po;
        po.size = 56;
        po.spacing = c.spacing;
        const core::Volume v = core::makePhantom("sphere", po);
        const core::SphereFacts f = core::spherePhantomFacts(v.geometry());
        const float sigma = float(1.0 / (2 * f.radius));  // τ = 1 through the centre
        const int n = 24;
        const render::Camera cam = orthoCamera(v, c.azimuth, c.elevation, 2.4 * f.radius, n);
        const core::ImageRGBA img = renderWith(v, stepTf(sigma), cam, eaOptions(c.stepVoxels));
        int checked = 0;
        for (int y = 0; y < n; ++y)
            for (int x = 0; x < n; ++x) {
                const render::Ray r = cam.generate(x, y);
                const double d = glm::length(glm::cross(f.centre - r.origin, r.direction));
                // The 0.5-level set is exact, but near the rim a chord grazes the ±1-voxel ramp
                // over a long, strongly curved stretch, where no sampling of the trilinear field
                // is linear; the closed form is checked where the chord is well inside.
                const double rim = 3.0 * c.spacing.x;
                if (std::abs(d - f.radius) < rim) continue;
                const double L = d < f.radius ? 2 * std::sqrt(f.radius * f.radius - d * d) : 0;
                EXPECT_NEAR(1.0 - img.at(x, y)[3], std::exp(-sigma * L), kTransmittanceTol)
                    << "step " << c.stepVoxels << " pixel " << x << "," << y << " d " << d;
                ++checked;
            }
        EXPECT_GT(checked, n * n / 2);
    }
}

namespace {
/// A homogeneous sphere (value 1 inside, 0 outside) on a 0.3 × 0.3 × 5 mm grid, built here because
/// the sphere phantom's ramp spans ±(smallest spacing) = ±0.3 mm, far narrower than a 5 mm slice.
/// The value is linear in the signed distance d over ±kRampMm, wider than any cell's diagonal
/// (≈ 5.02 mm), so every corner of every cell the surface crosses lies on the linear part and the
/// trilinear 0.5-level set is the 0.5-level set of the trilinearly interpolated d.
constexpr glm::dvec3 kAnisoSpacing{0.3, 0.3, 5.0};
constexpr double kAnisoRadius = 60.0;  // mm: 24 slices across, well resolved at 5 mm
constexpr double kRampMm = 6.0;

core::Volume anisotropicSphere(glm::dvec3& centre) {
    core::Geometry g;
    const double half = kAnisoRadius + kRampMm + 4.0;  // the ramp's far end stays inside
    g.dims = glm::ivec3(glm::ceil(2.0 * half / kAnisoSpacing)) + 1;
    g.spacing = kAnisoSpacing;
    g.origin = -0.5 * glm::dvec3(g.dims - 1) * g.spacing;
    core::Volume v(g, core::VoxelType::Float32);
    v.modality = core::Modality::Synthetic;
    // Off the grid's symmetry, so the poles and equator do not fall on voxel centres or slices.
    centre = glm::dvec3(0.11, -0.07, 1.3);
    float* out = v.dataAs<float>();
    for (int k = 0; k < g.dims.z; ++k)
        for (int j = 0; j < g.dims.y; ++j)
            for (int i = 0; i < g.dims.x; ++i) {
                const double d = glm::length(g.indexToWorld({i, j, k}) - centre) - kAnisoRadius;
                out[v.linearIndex(i, j, k)] = float(std::clamp(0.5 - 0.5 * d / kRampMm, 0.0, 1.0));
            }
    return v;
}
}  // namespace

TEST(ExactOptics, SphereTransmittanceMatchesChordLengthAtAnisotropicSpacing) {
    // Why not kTransmittanceTol: the trilinear interpolant of the signed distance d is not d.
    // Across a slice gap Δz it overestimates d by up to Δz²/8 · ∂²d/∂z² ≤ Δz²/(8R) = 0.052 mm (zero
    // on the slices), so the reconstructed sphere is up to 0.052 mm smaller between slices:
    // (Δz/Δx)² = 278× the in-plane shift, while 1e-3 bounds voxel-scale shifts of ~1 mm isotropic
    // voxels (the cases above). Pre-integration takes the field as linear between samples, which
    // adds up to Δs²/(8R) along the ray (0.048 mm at the largest step here, 16 × 0.3 mm). A shift ε
    // of the surface lengthens or shortens a chord of half-length h by ≤ 2ε·R/h, so |ΔT| ≤
    // e^(−h/R)·σ·2εR/h = ε·e^(−h/R)/h with σ = 1/(2R). Checking only chords that pass ≥ kAnisoRimMm
    // inside the rim (h ≥ 33 mm), ε ≤ 0.1 mm gives |ΔT| ≤ 1.7e-3.
    // Measured max |ΔT| at steps 0.5, 1, 2.5, 8, 16: 6.8e-4, 8.8e-4, 7.3e-4, 6.1e-4, 9.9e-4; it
    // rises to 3e-2 on grazing chords. A 1% error in σt shifts T by up to 3.7e-3 and fails.
    constexpr double kAnisoTransmittanceTol = 2e-3;
    constexpr double kAnisoRimMm = 2 * kAnisoSpacing.z;
    glm::dvec3 centre;
    const core::Volume v = anisotropicSphere(centre);
    const float sigma = float(1.0 / (2 * kAnisoRadius));  // τ = 1 through the centre
    const Case cases[] = {{kAnisoSpacing, 0.5f, 30, 20},
                          {kAnisoSpacing, 1.0f, 0, 0},
                          {kAnisoSpacing, 2.5f, 110, -35},
                          {kAnisoSpacing, 8.0f, 200, 60},
                          {kAnisoSpacing, 16.0f, 75, 90}};
    for (const Case& c : cases) {
        const int n = 32;
        const render::Camera cam = orthoCamera(v, c.azimuth, c.elevation, 2.3 * kAnisoRadius, n);
        const core::ImageRGBA img = renderWith(v, stepTf(sigma), cam, eaOptions(c.stepVoxels));
        int checked = 0;
        for (int y = 0; y < n; ++y)
            for (int x = 0; x < n; ++x) {
                const render::Ray r = cam.generate(x, y);
                const double d = glm::length(glm::cross(centre - r.origin, r.direction));
                if (std::abs(d - kAnisoRadius) < kAnisoRimMm) continue;  // grazing: see above
                const double L =
                    d < kAnisoRadius ? 2 * std::sqrt(kAnisoRadius * kAnisoRadius - d * d) : 0;
                EXPECT_NEAR(1.0 - img.at(x, y)[3], std::exp(-sigma * L), kAnisoTransmittanceTol)
                    << "step " << c.stepVoxels << " view " << c.azimuth << "/" << c.elevation
                    << " pixel " << x << "," << y << " d " << d;
                checked += d < kAnisoRadius;
            }
        EXPECT_GT(checked, n * n / 3);  // the disc of chords that are checked is ≈ 41% of the view
    }
}

TEST(ExactOptics, PreintegratedCoarseStepsAgreeWithFineSteppingOfASharpTf) {
    const core::Volume v = spherePhantom(40);
    const core::SphereFacts f = core::spherePhantomFacts(v.geometry());
    const auto tf = stepTf(float(2.0 / f.radius));  // τ = 4 through the centre
    const render::Camera cam = orthoCamera(v, 20, 10, 2.3 * f.radius, 20);
    render::RenderOptions coarse = eaOptions(2.0f), fine = eaOptions(0.02f), naive = coarse;
    fine.preintegrated = false;
    naive.preintegrated = false;
    const core::ImageRGBA a = renderWith(v, tf, cam, coarse), b = renderWith(v, tf, cam, fine),
                          c = renderWith(v, tf, cam, naive);
    double maxPre = 0, maxNaive = 0;
    for (int y = 0; y < 20; ++y)
        for (int x = 0; x < 20; ++x) {
            const render::Ray r = cam.generate(x, y);
            const double d = glm::length(glm::cross(f.centre - r.origin, r.direction));
            if (std::abs(d - f.radius) < 2.0) continue;  // grazing chords: see the sphere test
            for (int k = 0; k < 4; ++k) {
                maxPre = std::max(maxPre, double(std::abs(a.at(x, y)[k] - b.at(x, y)[k])));
                maxNaive = std::max(maxNaive, double(std::abs(c.at(x, y)[k] - b.at(x, y)[k])));
            }
        }
    // Fine stepping at 1/100 voxel converges to ≈ 1e-3; pre-integration at 2 voxels must match it.
    constexpr double kAgreementTol = 3e-3;
    EXPECT_LT(maxPre, kAgreementTol);
    // Without pre-integration the same coarse step visibly aliases (the reason it exists).
    EXPECT_GT(maxNaive, 5 * kAgreementTol);
}

TEST(ClipPlanes, PlaneThroughTheCentreRemovesExactlyHalfTheSphere) {
    const core::Volume v = spherePhantom(48);
    const core::SphereFacts f = core::spherePhantomFacts(v.geometry());
    const auto tf = stepTf(5.f);  // opaque
    render::RenderOptions o = eaOptions(0.5f);
    o.clipPlanes.push_back({f.centre, {1, 0, 0}});  // keep x ≥ centre (patient left half)
    const int n = 64;
    const double h = 2.2 * f.radius, px = h / n;
    // Top view: count covered pixels vs pixel centres inside the right half-disc.
    const render::Camera top = orthoCamera(v, 0, 90, h, n);
    const core::ImageRGBA img = renderWith(v, tf, top, o);
    int covered = 0, expected = 0, rim = 0;
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
            const render::Ray r = top.generate(x, y);
            const glm::dvec3 q = r.origin - f.centre;
            const double d = std::hypot(q.x, q.y);
            const bool kept = q.x >= 0;
            covered += img.at(x, y)[3] > 0.5f;
            expected += kept && d < f.radius;
            rim += kept && std::abs(d - f.radius) < 0.5 * px;
            if (!kept) {
                EXPECT_EQ(img.at(x, y)[3], 0.f) << "clipped half must be empty";
            }
        }
    EXPECT_NEAR(covered, expected, rim);
    EXPECT_GT(expected, 1000);
    // Looking at the cut face: a full disc, evenly lit (the plane normal replaces the vanishing
    // gradient of the homogeneous interior).
    render::RenderOptions g = o;
    g.mode = render::Mode::Gradient;
    const render::Camera side = orthoCamera(v, -90, 0, h, n);  // from patient right (−x)
    const core::ImageRGBA face = renderWith(v, tf, side, g);
    double sum = 0, sum2 = 0;
    int inside = 0, faceCovered = 0;
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
            const render::Ray r = side.generate(x, y);
            const glm::dvec3 q = r.origin - f.centre;
            const double d = std::hypot(q.y, q.z);
            faceCovered += face.at(x, y)[3] > 0.5f;
            if (d < 0.8 * f.radius) {
                sum += face.at(x, y)[1];
                sum2 += face.at(x, y)[1] * face.at(x, y)[1];
                ++inside;
            }
        }
    const double mean = sum / inside, sd = std::sqrt(std::max(0.0, sum2 / inside - mean * mean));
    EXPECT_GT(mean, 0.3);
    EXPECT_LT(sd, 0.01 * mean + 1e-4) << "cut face should be flat-shaded";
    EXPECT_NEAR(faceCovered, 2 * expected, 2 * rim + 4);
}

// smallTorso() and boneRampTf() (render_test_util.h): a transparent tail, a red soft ramp and
// opaque bone, so that every mode and the skipping have something to do.
TEST(Determinism, SameImageBitForBitWithOneAndTwoThreads) {
    const core::Volume v = smallTorso();
    const auto tf = boneRampTf();
    render::CameraSpec s;
    const auto b = v.geometry().worldBounds();
    const render::Camera cam(s, b[0], b[1], 48, 40);
    for (render::Mode m : {render::Mode::Gradient, render::Mode::EmissionAbsorption,
                           render::Mode::Isosurface, render::Mode::Mip}) {
        render::RenderOptions o;
        o.mode = m;
        o.tileSize = 8;
        o.threads = 1;
        const core::ImageRGBA one = renderWith(v, tf, cam, o);
        o.threads = 2;
        const core::ImageRGBA two = renderWith(v, tf, cam, o);
        ASSERT_EQ(one.pixels.size(), two.pixels.size());
        EXPECT_EQ(
            0, std::memcmp(one.pixels.data(), two.pixels.data(), one.pixels.size() * sizeof(float)))
            << render::toString(m);
    }
}

TEST(EmptySpaceSkipping, DoesNotChangeTheImage) {
    const core::Volume v = smallTorso();
    const auto tf = boneRampTf();
    render::CameraSpec s;
    const auto b = v.geometry().worldBounds();
    const render::Camera cam(s, b[0], b[1], 40, 40);
    for (render::Mode m : {render::Mode::Gradient, render::Mode::Isosurface, render::Mode::Mip,
                           render::Mode::MinIp}) {
        render::RenderOptions o;
        o.mode = m;
        render::RenderStats with, without;
        const core::ImageRGBA a = renderWith(v, tf, cam, o, &with);
        o.emptySpaceSkipping = false;
        const core::ImageRGBA c = renderWith(v, tf, cam, o, &without);
        double maxDiff = 0;
        for (std::size_t i = 0; i < a.pixels.size(); ++i)
            maxDiff = std::max(maxDiff, double(std::abs(a.pixels[i] - c.pixels[i])));
        // Skipping only drops segments whose both ends lie in TF-transparent bricks.
        EXPECT_LT(maxDiff, 1e-4) << render::toString(m);
        if (m == render::Mode::Gradient) {
            EXPECT_LT(with.samples, without.samples);
        }
    }
}

// RayCaster::visibleRange clips rays to the box of the non-empty skip cells: brute force along
// every ray of a 48² view, every position (0.05-voxel steps) inside a non-empty cell lies within
// the clipped [t0, t1], and the box is no larger than the non-empty cells' extent.
TEST(EmptySpaceSkipping, VisibleRangeKeepsEveryNonEmptyCell) {
    const core::Volume v = spherePhantom(64);
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    const auto tf = stepTf(1.f);
    const render::RayCaster caster(v, g, tf, render::RenderOptions{});
    const grid::BrickMajorants& m = caster.majorants();
    auto nonEmptyAt = [&](const glm::vec3& p) { return inNonEmptyCell(m, p); };
    ASSERT_GT(m.nonEmptyCount(), 0u);
    ASSERT_LT(m.nonEmptyCount(), m.size());  // the box must be a real clip here
    const auto& box = caster.visibleIndexBox();
    for (int a = 0; a < 3; ++a) EXPECT_LT(box[1][a] - box[0][a], float(v.geometry().dims[a] - 1));
    const render::Camera cam = orthoCamera(v, 35, 25, 70, 48);
    int clipped = 0, checked = 0;
    for (int y = 0; y < 48; ++y)
        for (int x = 0; x < 48; ++x) {
            const render::RaySegment r = caster.setupRay(cam, x, y);
            if (!r.hit()) continue;
            float t0 = 0.f, t1 = 0.f;
            const bool any = caster.visibleRange(r, t0, t1);
            if (any) {
                EXPECT_GE(t0, r.tNear);
                EXPECT_LE(t1, r.tFar);
                clipped += (t0 > r.tNear || t1 < r.tFar) ? 1 : 0;
            }
            const float dt = 0.05f / glm::length(r.dirIndex);
            for (float t = r.tNear; t <= r.tFar; t += dt) {
                if (!nonEmptyAt(r.originIndex + t * r.dirIndex)) continue;
                ++checked;
                ASSERT_TRUE(any) << x << "," << y << " t=" << t;
                ASSERT_GE(t, t0 - 1e-4f) << x << "," << y;
                ASSERT_LE(t, t1 + 1e-4f) << x << "," << y;
            }
        }
    EXPECT_GT(clipped, 100);   // most rays are shortened
    EXPECT_GT(checked, 1000);  // and many positions were checked
}
