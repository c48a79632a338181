// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <type_traits>

#include "core/error.h"
#include "core/rng.h"
#include "io/image.h"
#include "lights/environment_light.h"
#include "sh/sh_basis.h"
#include "sh/sh_rotation.h"
#include "support/equirect_patches.h"
#include "support/test_support.h"

using namespace voxlight;
using namespace voxlight::lights;

namespace {
constexpr double kPi = std::numbers::pi;

/// An environment light from an HDR file, as the pipeline builds one.
EnvironmentLight loadEnvironment(const std::filesystem::path& path,
                                 const EnvironmentOptions& options = {}) {
    return EnvironmentLight(io::readHdrImage(path), options, path.string());
}
// The bar: env projection vs brute force over all pixels, relative to the largest
// coefficient.
constexpr double kEnvRelTol = 1e-4;
// The same texel times the scale 2.5 in float: values ≤ 10, ulp ≤ 1e-6.
constexpr double kScaledLookupTol = 1e-5;
// Cached-rotation SH vs rotating the plain light's SH: float coefficients of size ≤ ~10 through
// the same blocks, scaled before vs after.
constexpr double kRotatedShTol = 1e-4;
// Energy-conserving DSF projection: Σ A_k s_k = Σ_p L_p Ω_p exactly up to float rounding.
constexpr double kEnergyRelTol = 1e-5;
// Importance sampling of a grey map: value/pdf = Σ lum Ω exactly in double; float value and pdf
// (and pdf() recomputed through the float wi) round at ~1e-7.
constexpr double kSampleWeightRelTol = 1e-4;
constexpr double kPdfRelTol = 1e-6;
// Pixel hit counts within 5σ of the binomial, plus one count for tiny expectations.
constexpr double kHitSigmas = 5.0;
// A missing or inverted rotation must be off by this many times the smooth-map tolerance.
constexpr double kInverseSeparation = 20.0;
// Nearest equirect texel of a bilinear resample of a 256² probe: ≈ 1° steps of a gradient 0.6/rad.
constexpr double kProbeLookupTol = 0.03;

core::ImageRGBA randomEquirect(int w, int h, std::uint64_t seed) {
    core::ImageRGBA img(w, h);
    core::CounterRng rng(seed);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            float* p = img.at(x, y);
            p[0] = rng.uniform() * 4, p[1] = rng.uniform(), p[2] = rng.uniform() * 0.5f, p[3] = 1;
        }
    return img;
}

glm::dmat3 rotationZyz(double a, double b, double g) {
    auto rz = [](double t) {
        return glm::dmat3(std::cos(t), std::sin(t), 0, -std::sin(t), std::cos(t), 0, 0, 0, 1);
    };
    auto ry = [](double t) {
        return glm::dmat3(std::cos(t), 0, -std::sin(t), 0, 1, 0, std::sin(t), 0, std::cos(t));
    };
    return rz(a) * ry(b) * rz(g);
}

// Brute-force SH projection over every pixel of the light's grid (per-pixel recurrence, not the
// separable path), each pixel a constant over its patch as the projection takes it (6² points).
std::vector<glm::dvec3> bruteForceSh(const EnvironmentLight& env, int band) {
    std::vector<glm::dvec3> c(sh::shCount(band), glm::dvec3(0.0));
    test::forEachEquirectPatchSh(
        band, env.width(), env.height(), env.rotation(), 6,
        [&](int row, int col, const std::vector<double>& y) {
            const glm::dvec3 v = glm::dvec3(env.texels()[std::size_t(row) * env.width() + col]) *
                                 double(env.scale());
            for (std::size_t k = 0; k < c.size(); ++k) c[k] += v * y[k];
        });
    return c;
}

void expectShMatchesBruteForce(const EnvironmentLight& env, int band) {
    const auto fast = env.shCoefficients({0, 0, 0}, band);
    const auto ref = bruteForceSh(env, band);
    double scale = 0;
    for (const auto& v : ref)
        scale = std::max({scale, std::abs(v.x), std::abs(v.y), std::abs(v.z)});
    for (std::size_t i = 0; i < ref.size(); ++i)
        for (int ch = 0; ch < 3; ++ch)
            ASSERT_NEAR(fast[i][ch], ref[i][ch], kEnvRelTol * scale)
                << env.toString() << " i=" << i;
}
}  // namespace

TEST(EnvironmentLight, PixelLookupRoundTripAndOrientation) {
    const auto img = randomEquirect(64, 32, 1);
    const EnvironmentLight env(img, {}, "random");
    for (int r = 0; r < 32; ++r)
        for (int c = 0; c < 64; ++c) {
            const glm::dvec3 d =
                sh::sphericalToDirection(kPi * (r + 0.5) / 32, kPi - 2 * kPi * (c + 0.5) / 64);
            ASSERT_EQ(env.lookup(glm::vec3(d)).x, img.at(c, r)[0]) << c << "," << r;
        }
    // Image centre looks along +x, top row is +z, the column right of centre is toward −y.
    EXPECT_EQ(env.lookup({1, 0, 0}).x, img.at(32, 16)[0]);
    EXPECT_EQ(env.lookup({0, 0, 1}).x,
              img.at(32, 0)[0]);  // φ = atan2(0, 0) = 0 → the centre column
    EXPECT_EQ(env.lookup({0, 0, -1}).x, img.at(32, 31)[0]);
    EXPECT_EQ(env.lookup(glm::normalize(glm::vec3(1, -0.05f, 0))).x, img.at(32, 16)[0]);
    EXPECT_EQ(env.lookup(glm::normalize(glm::vec3(1, 0.05f, 0))).x, img.at(31, 16)[0]);
}

TEST(EnvironmentLight, RotationAndScale) {
    const auto img = randomEquirect(64, 32, 2);
    EnvironmentOptions opt;
    opt.rotation = rotationZyz(0.3, 1.1, -0.8);
    opt.scale = 2.5f;
    const EnvironmentLight rotated(img, opt, "rotated");
    const EnvironmentLight plain(img, {}, "plain");
    core::CounterRng rng(4);
    for (int i = 0; i < 1000; ++i) {
        const glm::dvec3 d = sh::sphericalToDirection(std::acos(1 - 2 * rng.uniformDouble()),
                                                      2 * kPi * rng.uniformDouble());
        ASSERT_NEAR(rotated.lookup(glm::vec3(opt.rotation * d)).x,
                    2.5f * plain.lookup(glm::vec3(d)).x, kScaledLookupTol);
    }
    // SH of the rotated light = rotated SH of the plain light (the cached rotation) = brute force.
    const auto a = rotated.shCoefficients({}, 6), b = plain.shCoefficients({}, 6);
    std::vector<glm::vec3> br(b.size());
    sh::ShRotation(opt.rotation, 6).applyRgb(b, br);
    for (std::size_t i = 0; i < a.size(); ++i)
        EXPECT_NEAR(a[i].x, 2.5f * br[i].x, kRotatedShTol) << i;
    expectShMatchesBruteForce(rotated, 8);
    // Bands above the cache are projected on demand.
    expectShMatchesBruteForce(rotated, 10);
    // DSF: rotation by resampling keeps the integral.
    const sh::Dsf dsf(162);
    const glm::dvec3 ia = dsf.integrate(rotated.dsfCoefficients({}, dsf)),
                     ib = dsf.integrate(plain.dsfCoefficients({}, dsf));
    EXPECT_NEAR(ia.x, 2.5 * ib.x, kEnergyRelTol * ia.x);
    EXPECT_NEAR(ia.x, a[0].x * std::sqrt(4 * kPi), kEnergyRelTol * ia.x);
    EXPECT_THROW(EnvironmentLight(img, EnvironmentOptions{.scale = -1.0f}, "x"), InputError);
    EXPECT_THROW(EnvironmentLight(img, EnvironmentOptions{.rotation = glm::dmat3(2.0)}, "x"),
                 InputError);
}

TEST(EnvironmentLight, DsfCoefficientsFollowTheRotation) {
    // The DSF integral is rotation-invariant, so RotationAndScale cannot tell a correct rotation
    // from none or an inverted one. Here the map is smooth, f(ω_map) = 1 + 0.5 a·ω_map, so the
    // energy-conserving coefficient at a DSF direction ω_k must be ≈ f(Rᵀ ω_k) — the radiance
    // arriving from world direction ω_k.
    // The basis' weighted mean of a linear function is off-centre by a fraction of h ≈ 0.12 rad
    // (n = 642): measured ≤ 0.0022 in f, 0.0044 after the scale of 2. A missing or inverted
    // rotation is off by up to ~1.
    constexpr double kSmoothDsfTol = 0.01;
    constexpr int kW = 256, kH = 128;
    const glm::dvec3 a = glm::normalize(glm::dvec3(0.8, -0.3, 0.5));
    auto f = [&](const glm::dvec3& mapDir) { return 1.0 + 0.5 * glm::dot(a, mapDir); };
    core::ImageRGBA img(kW, kH);
    for (int r = 0; r < kH; ++r)
        for (int c = 0; c < kW; ++c) {
            const glm::dvec3 d =
                sh::sphericalToDirection(kPi * (r + 0.5) / kH, kPi - 2 * kPi * (c + 0.5) / kW);
            float* p = img.at(c, r);
            p[0] = p[1] = p[2] = float(f(d));
            p[3] = 1;
        }
    const glm::dmat3 rot = rotationZyz(0.7, 1.3, -0.4);
    const EnvironmentLight env(img, {.rotation = rot, .scale = 2.0f}, "smooth");
    const sh::Dsf dsf(642);
    const auto s = env.dsfCoefficients({}, dsf);
    double worst = 0, worstInverse = 0;
    for (int k = 0; k < dsf.size(); ++k) {
        const glm::dvec3 w = dsf.directions()[k];
        worst = std::max(worst, std::abs(s[k].x - 2.0 * f(glm::transpose(rot) * w)));
        worstInverse = std::max(worstInverse, std::abs(s[k].x - 2.0 * f(rot * w)));
    }
    RecordProperty("dsf_rotation_error", std::to_string(worst));
    EXPECT_LT(worst, kSmoothDsfTol);
    EXPECT_GT(worstInverse,
              kInverseSeparation * kSmoothDsfTol);  // the test can tell the two directions apart
}

TEST(EnvironmentLight, DsfProjectionIsCachedPerSizeAndRotation) {
    static_assert(std::is_nothrow_move_constructible_v<EnvironmentLight> &&
                  std::is_nothrow_move_assignable_v<EnvironmentLight>);
    const auto img = randomEquirect(64, 32, 7);
    const glm::dmat3 r1 = rotationZyz(0.3, 1.1, -0.8), r2 = rotationZyz(1.0, 0.2, 0.5);
    EnvironmentLight env(img, {.rotation = r1}, "cached");
    const sh::Dsf dsf(162), coarse(42);
    EXPECT_EQ(env.dsfProjectionCount(), 0u);
    const auto first = env.dsfCoefficients({0, 0, 0}, dsf);
    EXPECT_EQ(env.dsfProjectionCount(), 1u);
    // Another point, same light: served from the cache, bit-identical.
    EXPECT_EQ(env.dsfCoefficients({5, -3, 2}, dsf), first);
    EXPECT_EQ(env.dsfProjectionCount(), 1u);
    // The scale is applied after the cache: no re-projection.
    env.setScale(2.0f);
    const auto scaled = env.dsfCoefficients({}, dsf);
    EXPECT_EQ(env.dsfProjectionCount(), 1u);
    for (int k = 0; k < dsf.size(); ++k) EXPECT_EQ(scaled[k], 2.0f * first[k]) << k;
    // Each DSF size has its own entry.
    EXPECT_EQ(env.dsfCoefficients({}, coarse).size(), 42u);
    EXPECT_EQ(env.dsfProjectionCount(), 2u);
    EXPECT_EQ(env.dsfCoefficients({}, dsf), scaled);
    EXPECT_EQ(env.dsfProjectionCount(), 2u);
    // A new rotation invalidates the entry; the result is that of a light made with it.
    env.setRotation(r2);
    const auto rotated = env.dsfCoefficients({}, dsf);
    EXPECT_EQ(env.dsfProjectionCount(), 3u);
    EXPECT_NE(rotated, scaled);
    const EnvironmentLight fresh(img, {.rotation = r2, .scale = 2.0f}, "fresh");
    EXPECT_EQ(rotated, fresh.dsfCoefficients({}, dsf));
    // Setting the same rotation again keeps the entry.
    env.setRotation(r2);
    EXPECT_EQ(env.dsfCoefficients({}, dsf), rotated);
    EXPECT_EQ(env.dsfProjectionCount(), 3u);
    // A moved-to light keeps its cache.
    const EnvironmentLight moved = std::move(env);
    EXPECT_EQ(moved.dsfCoefficients({}, dsf), rotated);
    EXPECT_EQ(moved.dsfProjectionCount(), 3u);
}

TEST(EnvironmentLight, NearRotationIsStoredOrthonormal) {
    // lookup() and pdf() invert the rotation by its transpose, so the stored matrix must be
    // orthonormal to rounding (sums of three products ~1e-16), not only to checkRotation's 1e-4.
    constexpr double kOrthonormalTol = 1e-14;
    glm::dmat3 skewed = rotationZyz(0.3, 1.1, -0.8);
    skewed[0][2] += 4e-5, skewed[1][0] -= 3e-5;
    const EnvironmentLight env(randomEquirect(64, 32, 9), {.rotation = skewed}, "skewed");
    EXPECT_EQ(env.rotation(), sh::orthonormalizeRotation(skewed));
    const glm::dmat3 rtr = glm::transpose(env.rotation()) * env.rotation();
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) EXPECT_NEAR(rtr[i][j], i == j, kOrthonormalTol) << i << j;
    EXPECT_NEAR(glm::determinant(env.rotation()), 1.0, kOrthonormalTol);
}

TEST(EnvironmentLight, ImportanceSamplingIsExact) {
    // Grey map: value/pdf = Σ lum Ω for every sample (zero variance), and pixel frequencies follow
    // lum·Ω.
    constexpr int kW = 16, kH = 8;
    core::ImageRGBA img(kW, kH);
    core::CounterRng rng(5);
    double integral = 0;
    std::vector<double> prob(kW * kH);
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
            const float v = (x + y) % 5 == 0 ? 0.0f : 0.1f + rng.uniform() * (y == 2 ? 20 : 1);
            float* p = img.at(x, y);
            p[0] = p[1] = p[2] = v;
            const double omega =
                2 * kPi / kW * (std::cos(kPi * y / kH) - std::cos(kPi * (y + 1) / kH));
            integral += v * omega;
            prob[y * kW + x] = v * omega;
        }
    const EnvironmentLight env(img, {.rotation = rotationZyz(1, 2, 3)}, "grey");
    std::vector<int> hits(kW * kH, 0);
    constexpr int kN = 200000;
    for (int i = 0; i < kN; ++i) {
        core::CounterRng r(i, 8);
        const LightSample s = env.sample({}, {r.uniform(), r.uniform()});
        ASSERT_GT(s.pdf, 0.0f);
        ASSERT_NEAR(s.value.x / s.pdf, integral, kSampleWeightRelTol * integral);
        ASSERT_NEAR(env.pdf({}, s.wi), s.pdf, kPdfRelTol * s.pdf);
        // Which pixel (map frame) was hit.
        const glm::dvec3 m = glm::transpose(env.rotation()) * glm::dvec3(s.wi);
        const int row = std::min(kH - 1, int(std::acos(std::clamp(m.z, -1.0, 1.0)) / kPi * kH));
        int col = int(std::floor((kPi - std::atan2(m.y, m.x)) / (2 * kPi) * kW));
        col = ((col % kW) + kW) % kW;
        ++hits[row * kW + col];
    }
    for (int p = 0; p < kW * kH; ++p) {
        const double expected = kN * prob[p] / integral;
        EXPECT_NEAR(hits[p], expected, kHitSigmas * std::sqrt(expected) + 1) << "pixel " << p;
    }
}

TEST(EnvironmentLight, AngularProbeLayout) {
    // Render f(ω) = 1 + 0.5 ω_x + 0.3 ω_z into a probe; the loaded light must reproduce it.
    constexpr int kS = 256;
    core::ImageRGBA probe(kS, kS);
    auto f = [](const glm::dvec3& d) { return 1.0 + 0.5 * d.x + 0.3 * d.z; };
    for (int y = 0; y < kS; ++y)
        for (int x = 0; x < kS; ++x) {
            const double u = 2.0 * (x + 0.5) / kS - 1.0, v = 1.0 - 2.0 * (y + 0.5) / kS;
            const double rho = std::min(1.0, std::hypot(u, v)), a = kPi * rho;
            // Centre +x, right −y, up +z.
            const glm::dvec3 d = rho > 0
                                     ? glm::dvec3(std::cos(a), -std::sin(a) * u / std::hypot(u, v),
                                                  std::sin(a) * v / std::hypot(u, v))
                                     : glm::dvec3(1, 0, 0);
            float* p = probe.at(x, y);
            p[0] = p[1] = p[2] = float(f(d));
            p[3] = 1;
        }
    const EnvironmentLight env(probe, {.layout = EnvironmentLayout::AngularProbe}, "probe");
    EXPECT_EQ(env.width(), 2 * kS);
    core::CounterRng rng(6);
    for (int i = 0; i < 2000; ++i) {
        const glm::dvec3 d = sh::sphericalToDirection(std::acos(1 - 2 * rng.uniformDouble()),
                                                      2 * kPi * rng.uniformDouble());
        if (d.x < -0.95)
            continue;  // the back pole is one ring of the probe: resolution there is poor
        ASSERT_NEAR(env.lookup(glm::vec3(d)).x, f(d), kProbeLookupTol)
            << d.x << "," << d.y << "," << d.z;
    }
    EXPECT_THROW(EnvironmentLight(randomEquirect(64, 32, 1),
                                  {.layout = EnvironmentLayout::AngularProbe}, "x"),
                 InputError);
}

TEST(EnvironmentLight, BadInputIsAClearError) {
    test::TempDir tmp;
    // Missing file.
    EXPECT_THROW(loadEnvironment(tmp / "missing.hdr"), InputError);
    // Corrupt .hdr: a Radiance header followed by garbage.
    {
        std::ofstream out(tmp / "corrupt.hdr", std::ios::binary);
        out << "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 512 +X 1024\n" << std::string(100, '\x07');
    }
    try {
        loadEnvironment(tmp / "corrupt.hdr");
        FAIL() << "corrupt file accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("corrupt.hdr"), std::string::npos) << e.what();
    }
    // Not HDR: an 8-bit PNG.
    core::ImageRGBA small(8, 4);
    io::writeImage(small, tmp / "ldr.png");
    try {
        loadEnvironment(tmp / "ldr.png");
        FAIL() << "8-bit map accepted";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "format");
        EXPECT_NE(std::string(e.what()).find("ldr.png"), std::string::npos);
    }
    // Zero size, NaN, Inf, negative, wrong aspect.
    EXPECT_THROW(EnvironmentLight(core::ImageRGBA{}, {}, "empty"), InputError);
    // Brighter than kMaxRadiance: the SH methods' image went black (float overflow) from 1e20 on.
    for (float bad : {NAN, INFINITY, -1.0f, 1e16f, 3e38f}) {
        auto img = randomEquirect(16, 8, 3);
        img.at(5, 3)[1] = bad;
        try {
            EnvironmentLight(img, {}, "bad.exr");
            FAIL() << "bad pixel accepted: " << bad;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find("pixel (5, 3) channel G"), std::string::npos)
                << e.what();
            EXPECT_NE(std::string(e.what()).find("bad.exr"), std::string::npos);
        }
    }
    // The limit is on the radiance the light gives (texel × colour·intensity): a bright map
    // dimmed is fine; one a large intensity pushes past it blames the light's intensity.
    {
        auto bright = randomEquirect(16, 8, 3);
        bright.at(4, 2)[0] = 1e16f;
        EXPECT_NO_THROW(EnvironmentLight::checkTexels(bright, "sun.exr", glm::vec3(1e-3f)));
        auto dim = randomEquirect(16, 8, 3);
        dim.at(4, 2)[2] = 1e10f;
        try {
            EnvironmentLight::checkTexels(dim, "sky.exr", glm::vec3(1.0f, 1.0f, 1e6f));
            FAIL() << "radiance 1e16 accepted";
        } catch (const InputError& e) {
            EXPECT_EQ(e.source(), "light");
            EXPECT_EQ(e.field(), "intensity");
            EXPECT_NE(std::string(e.what()).find("sky.exr's pixel (4, 2) channel B"),
                      std::string::npos)
                << e.what();
        }
        EXPECT_NO_THROW(EnvironmentLight::checkTexels(dim, "sky.exr", glm::vec3(1e6f, 1e5f, 1.0f)));
    }
    EXPECT_THROW(EnvironmentLight(randomEquirect(30, 20, 1), {}, "aspect"), InputError);
    // Lossy-compression noise (−1e-6 of a map with values up to 4) is accepted and zeroed, and
    // counted.
    auto noisy = randomEquirect(16, 8, 3);
    noisy.at(2, 2)[0] = -1e-6f;
    const EnvironmentLight ok(noisy, {}, "noisy");
    EXPECT_EQ(ok.clampedTexels(), 1u);
    EXPECT_EQ(ok.texels()[2 * 16 + 2].x, 0.0f);
}

TEST(EnvironmentLight, RealHdrProbeProjection) {
    VL_REQUIRE_SHARED(city, "env/city.hdr");
    const EnvironmentLight env = loadEnvironment(city, {.rotation = rotationZyz(0.5, 0.4, 0.2)});
    EXPECT_EQ(env.width(), 1024);
    EXPECT_EQ(env.height(), 512);
    expectShMatchesBruteForce(env, 8);
    // DSF and SH agree on the total incident power ∫ L dω (energy-conserving DSF projection: to
    // float rounding).
    const sh::Dsf dsf(642);
    const glm::dvec3 p = dsf.integrate(env.dsfCoefficients({}, dsf));
    const auto c = env.shCoefficients({}, 0);
    EXPECT_NEAR(p.y, c[0].y * std::sqrt(4 * kPi), kEnergyRelTol * p.y);
}

TEST(EnvironmentLight, RealExrProbeLoads) {
    VL_REQUIRE_SHARED(studio, "env/studio.exr");
    const EnvironmentLight env = loadEnvironment(studio);
    EXPECT_EQ(env.width(), 1024);
    const auto c = env.shCoefficients({}, 4);
    EXPECT_GT(c[0].x, 0.0f);
    const LightSample s = env.sample({}, {0.3f, 0.7f});
    EXPECT_GT(s.pdf, 0.0f);
}
