// SPDX-License-Identifier: MIT
// Hard cases of lights and spherical harmonics (issue #17 item 4): point lights inside the volume
// and exactly on a voxel centre; directional lights exactly along ±x/±y/±z; SH rotations at gimbal
// lock; SH to band 8 at the poles; an environment map with a 10⁵:1 dynamic range. Through every
// method that takes the light, each render must be finite and non-negative (or a clear
// InputError from a method that does not take it); where a closed form or a brute-force sum is
// cheap, the value is compared with it.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <set>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/rng.h"
#include "io/image.h"
#include "lights/environment_light.h"
#include "lights/light.h"
#include "pipeline/scene_inputs.h"
#include "sh/sh_basis.h"
#include "sh/sh_projection.h"
#include "sh/sh_rotation.h"
#include "stability/hard_cases_util.h"
#include "support/equirect_patches.h"
#include "support/test_support.h"

using namespace voxlight;
using namespace voxlight::test;
using nlohmann::json;

namespace {
constexpr double kPi = std::numbers::pi;
constexpr int kBand = 8;  // the band for the SH cases

// Float evaluation (evalSh, evalShUnit, evalShFixed) of values ≤ ~1.4 at the poles: a few ulps.
constexpr double kFloatPoleTol = 2e-6;
// Double recurrence and textbook path at the poles: ~l rounding steps of values ≤ ~1.4.
constexpr double kDoublePoleTol = 1e-12;
// ShRotation in double against the exact (Gauss–Legendre) projection of the rotated band-limited
// function, coefficients of size ≤ 1 (test_sh_rotation's bar).
constexpr double kDoubleRotationTol = 1e-10;
// Float SH coefficients of a light (stored as glm::vec3) relative to the largest one: float
// rounding of the map projection's and the rotation's sums.
constexpr double kFloatCoeffRelTol = 2e-5;
// DC of the environment map against Σ L Ω in long double: one float rounding of the stored
// coefficient plus the double sum's, relative.
constexpr double kDcRelTol = 1e-6;
// Polar-row projection (float coefficients of size ≤ ~1) against its closed form.
constexpr double kCapTol = 1e-6;
// The light's pdf() at a sampled direction against the pdf sample() returned: float rounding of
// the luminance CDFs.
constexpr double kPdfRelTol = 1e-3;

/// Methods that take point lights (pipeline/raycast_methods.cpp header; pvrt precomputes for
/// distant lights only and refuses them): these must render, the others may refuse with an
/// InputError. Directional and environment lights every method must take.
const std::set<std::string> kPointLightMethods = {"gradient",  "iso",      "sh-local",
                                                  "sh-global", "ritschel", "pathtrace"};
std::set<std::string> everyMethod() {
    const auto m = allMethods();
    return {m.begin(), m.end()};
}

/// Renders `lights` through every method; the ones in `mustRender` may not refuse. Returns how
/// many rendered.
int renderEveryMethod(const std::filesystem::path& volume, const json& lights,
                      const std::set<std::string>& mustRender, const std::string& what,
                      const json& camera = nullptr) {
    int rendered = 0;
    for (const std::string& method : allMethods()) {
        const std::string w = what + " " + method;
        json d = hardScene(volume, methodOf(method), lights);
        if (!camera.is_null()) d["camera"] = camera;
        const auto r = renderOrRefuse(d, w);
        if (!r) {
            EXPECT_FALSE(mustRender.count(method)) << w << " refused a light it documents";
            continue;
        }
        expectSane(r->image, w);
        ++rendered;
    }
    return rendered;
}

/// Y_l^0 at the pole z = s (±1): √((2l+1)/4π) · s^l; every m ≠ 0 is 0.
double poleValue(int l, int m, double s) {
    if (m != 0) return 0.0;
    return std::sqrt((2.0 * l + 1.0) / (4.0 * kPi)) * ((s < 0 && l % 2) ? -1.0 : 1.0);
}

glm::dmat3 rotX(double a) {
    return glm::dmat3(1, 0, 0, 0, std::cos(a), std::sin(a), 0, -std::sin(a), std::cos(a));
}
glm::dmat3 rotY(double a) {
    return glm::dmat3(std::cos(a), 0, -std::sin(a), 0, 1, 0, std::sin(a), 0, std::cos(a));
}
glm::dmat3 rotZ(double a) {
    return glm::dmat3(std::cos(a), std::sin(a), 0, -std::sin(a), std::cos(a), 0, 0, 0, 1);
}
/// The scene's environment rotation (x, y, z Euler degrees: x, then y, then z, extrinsic).
glm::dmat3 sceneRotation(glm::dvec3 deg) {
    const glm::dvec3 r = glm::radians(deg);
    return rotZ(r.z) * rotY(r.y) * rotX(r.x);
}

/// A 10⁵:1 equirect map of 32 × 16: a dim sky of radiance 1 with a one-texel sun of
/// 10⁵ at (c, r) = (5, 3); RGB equal, alpha 1.
core::ImageRGBA sunAndSky() {
    core::ImageRGBA im(32, 16);
    for (int r = 0; r < im.height; ++r)
        for (int c = 0; c < im.width; ++c) {
            const float v = (c == 5 && r == 3) ? 1e5f : 1.f;
            float* p = im.at(c, r);
            p[0] = p[1] = p[2] = v, p[3] = 1.f;
        }
    return im;
}

/// Brute force: c_i = Σ_p L_p Ω_p Y_i(R ω_p) over the map's pixel centres (the map frame of
/// lights/environment_light.h: θ_r = π(r + ½)/H, φ_c = π − 2π(c + ½)/W), in long double. Equal to
/// rotating the midpoint-rule projection, because each band is closed under rotation.
std::vector<long double> bruteForceSh(const core::ImageRGBA& im, const glm::dmat3& r) {
    // Each pixel a constant over its patch (the projection's model): 8² Gauss–Legendre points per
    // patch — exact to ~1e-12 for band 8 on patches of 11°.
    std::vector<long double> c(sh::shCount(kBand), 0.0L);
    test::forEachEquirectPatchSh(kBand, im.width, im.height, r, 8,
                                 [&](int row, int col, const std::vector<double>& y) {
                                     const long double v = im.at(col, row)[0];
                                     for (std::size_t k = 0; k < c.size(); ++k) c[k] += v * y[k];
                                 });
    return c;
}

}  // namespace

TEST(HardCases, PointLightInsideTheVolumeAndOnAVoxelCentre) {
    const TempDir tmp;
    const auto volume = writeHard(kBall, tmp.path());
    // Voxel (4, 4, 4) is at (4, 4, 4) mm: a sample of every grid the methods build (voxels,
    // visibility points, bricks). (0, 0, 0) is a corner voxel; (4.5, 4.5, 4.5) lies between
    // voxels; the tiny min_distance makes the 1/d² clamp as sharp as the scene allows.
    struct Case {
        glm::dvec3 position;
        double minDistance;
    };
    const std::vector<Case> cases = {
        {{4, 4, 4}, 1.0}, {{4, 4, 4}, 1e-6}, {{0, 0, 0}, 1e-6}, {{4.5, 4.5, 4.5}, 1.0}};
    for (const Case& c : cases) {
        const json lights = json::array({{{"type", "point"},
                                          {"position", {c.position.x, c.position.y, c.position.z}},
                                          {"min_distance", c.minDistance},
                                          {"intensity", 20}}});
        const std::string what = "point light at (" + std::to_string(c.position.x) + ", …) rmin " +
                                 std::to_string(c.minDistance);
        EXPECT_GE(renderEveryMethod(volume, lights, kPointLightMethods, what),
                  int(kPointLightMethods.size()))
            << what;
    }
    // Closed form at the light itself: the SH of the incident radiance is isotropic with the
    // clamped irradiance, E = I / rmin², i.e. c_0 = E·Y_0 and every other coefficient 0
    // (lights/light.h PointLight).
    for (double rmin : {1.0, 1e-3}) {
        const lights::PointLight light(glm::vec3(2.f), {4, 4, 4}, rmin);
        const auto c = light.shCoefficients({4, 4, 4}, kBand);
        const double e = 2.0 / (rmin * rmin);
        EXPECT_NEAR(c[0].x, e * poleValue(0, 0, 1), kFloatCoeffRelTol * e) << rmin;
        for (std::size_t i = 1; i < c.size(); ++i)
            ASSERT_EQ(c[i], glm::vec3(0.f)) << "coefficient " << i << " rmin " << rmin;
        const lights::LightSample s = light.sample({4, 4, 4}, {0.5f, 0.5f});
        EXPECT_TRUE(std::isfinite(s.value.x) && s.value.x >= 0.f) << s.value.x;
        EXPECT_TRUE(std::isfinite(s.wi.x) && std::isfinite(s.wi.y) && std::isfinite(s.wi.z));
    }
}

TEST(HardCases, DirectionalLightsExactlyAlongTheAxes) {
    const TempDir tmp;
    const auto volume = writeHard(kBall, tmp.path());
    const std::vector<glm::dvec3> axes = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                          {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
    // Each axis under the default view (azimuth 30°, elevation 20°: along none of them) and with
    // the view exactly along the light's travel, the light behind the camera (for ±z the view is
    // parallel to the default up, +z).
    for (const glm::dvec3& a : axes) {
        const json lights = json::array(
            {{{"type", "directional"}, {"direction", {a.x, a.y, a.z}}, {"intensity", 3}}});
        const std::string what = "directional along (" + std::to_string(int(a.x)) + "," +
                                 std::to_string(int(a.y)) + "," + std::to_string(int(a.z)) + ")";
        EXPECT_GT(renderEveryMethod(volume, lights, everyMethod(), what), 0) << what;
        const glm::dvec3 eye = glm::dvec3(4.0) - 30.0 * a;
        const json camera = {{"eye", {eye.x, eye.y, eye.z}}, {"target", {4, 4, 4}}};
        EXPECT_GT(
            renderEveryMethod(volume, lights, everyMethod(), what + ", view along it", camera), 0)
            << what;
    }
    // Closed form: a directional light's SH is E·Y_i(ω_l) (Kronander eq. 10); at the six axes the
    // textbook Y_l^m(θ, φ) (evalShSlow) is the reference, with θ, φ of the axis.
    struct Axis {
        glm::vec3 toward;
        double theta, phi;
    };
    const std::vector<Axis> dirs = {{{1, 0, 0}, kPi / 2, 0},       {{-1, 0, 0}, kPi / 2, kPi},
                                    {{0, 1, 0}, kPi / 2, kPi / 2}, {{0, -1, 0}, kPi / 2, -kPi / 2},
                                    {{0, 0, 1}, 0, 0.7},           {{0, 0, -1}, kPi, -2.1}};
    for (const Axis& d : dirs) {
        const lights::DirectionalLight light(glm::vec3(3.f), d.toward);
        const auto c = light.shCoefficients({0, 0, 0}, kBand);
        for (int l = 0; l <= kBand; ++l)
            for (int m = -l; m <= l; ++m) {
                const double expected = 3.0 * sh::evalShSlow(l, m, d.theta, d.phi);
                ASSERT_NEAR(c[sh::shIndex(l, m)].x, expected, 3.0 * kFloatPoleTol)
                    << "toward " << d.toward.x << "," << d.toward.y << "," << d.toward.z
                    << " l=" << l << " m=" << m;
            }
    }
}

TEST(HardCases, ShRotationAtGimbalLock) {
    // Random band-8 function f; g = f∘R⁻¹ projected exactly (Gauss–Legendre with 9 nodes is exact
    // for products up to band 17) against ShRotation(R)·f, for the scene's x-y-z Euler rotation
    // at pitch ±90° (gimbal lock: x and z turn about the same axis) and the exact axis quarter
    // turns.
    std::vector<double> f(sh::shCount(kBand));
    core::CounterRng rng(17);
    for (double& x : f) x = 2.0 * rng.uniformDouble() - 1.0;
    const sh::SphereSamples q = sh::gaussLegendreSamples(9);
    std::vector<glm::dvec3> eulers;
    for (double pitch : {90.0, -90.0})
        for (double a : {0.0, 30.0, -45.0, 90.0})
            for (double b : {0.0, 60.0, 180.0}) eulers.push_back({a, pitch, b});
    for (double a : {90.0, -90.0, 180.0}) {
        eulers.push_back({a, 0, 0});
        eulers.push_back({0, 0, a});
    }
    for (const glm::dvec3& e : eulers) {
        const glm::dmat3 r = sceneRotation(e);
        const auto direct = sh::projectFunction(kBand, q, [&](const glm::dvec3& w) {
            return sh::shReconstructDouble(f, glm::transpose(r) * w);
        });
        std::vector<double> rotated(f.size());
        sh::ShRotation(r, kBand).apply(std::span<const double>(f), std::span<double>(rotated));
        for (std::size_t i = 0; i < f.size(); ++i) {
            ASSERT_TRUE(std::isfinite(rotated[i])) << i;
            ASSERT_NEAR(direct[i], rotated[i], kDoubleRotationTol)
                << "euler " << e.x << "," << e.y << "," << e.z << " i=" << i;
        }
    }
    // Through the scene: at pitch +90° the Euler triple (a, 90, b) is the rotation (0, 90, b − a)
    // (Ry(90)·Rx(a) = Rz(−a)·Ry(90)); at −90°, (a, −90, b) = (0, −90, b + a). Two descriptions of
    // one rotation must give one environment light.
    const TempDir tmp;
    const auto map = tmp / "sky.exr";
    io::writeImage(sunAndSky(), map);
    auto lightSh = [&](glm::dvec3 deg) {
        io::Scene s;
        io::LightDesc l;
        l.type = "environment";
        l.path = map;
        l.rotationDeg = deg;
        s.lights = {l};
        return pipeline::buildLights(s).at(0)->shCoefficients({0, 0, 0}, kBand);
    };
    for (const auto& [a, b] :
         std::vector<std::pair<glm::dvec3, glm::dvec3>>{{{30, 90, 75}, {0, 90, 45}},
                                                        {{-60, 90, 0}, {0, 90, 60}},
                                                        {{30, -90, 15}, {0, -90, 45}},
                                                        {{90, -90, 90}, {0, -90, 180}}}) {
        const auto ca = lightSh(a), cb = lightSh(b);
        const double scale = std::abs(ca[0].x);
        for (std::size_t i = 0; i < ca.size(); ++i)
            ASSERT_NEAR(ca[i].x, cb[i].x, kFloatCoeffRelTol * scale)
                << "(" << a.x << "," << a.y << "," << a.z << ") vs (" << b.x << "," << b.y << ","
                << b.z << ") i=" << i;
    }
}

TEST(HardCases, ShToBand8AtThePoles) {
    for (double s : {1.0, -1.0}) {
        const glm::vec3 pole(0.f, 0.f, float(s));
        std::vector<float> yf(sh::shCount(kBand)), yu(sh::shCount(kBand));
        std::vector<double> yd(sh::shCount(kBand));
        sh::evalSh(kBand, pole, yf);
        sh::evalShUnit(kBand, pole, yu);
        sh::evalShUnitDouble(kBand, glm::dvec3(pole), yd);
        // Signed zeros and an unnormalised pole (the checked path normalises) are the same pole.
        std::vector<float> yz(sh::shCount(kBand));
        sh::evalSh(kBand, glm::vec3(-0.f, -0.f, float(5 * s)), yz);
        std::array<float, sh::shCount(4)> fixed;
        sh::evalShFixed<4>(pole, fixed.data());
        for (int l = 0; l <= kBand; ++l)
            for (int m = -l; m <= l; ++m) {
                const int i = sh::shIndex(l, m);
                const double expected = poleValue(l, m, s);
                ASSERT_NEAR(yf[i], expected, kFloatPoleTol) << "evalSh s=" << s << " i=" << i;
                ASSERT_NEAR(yu[i], expected, kFloatPoleTol) << "evalShUnit i=" << i;
                ASSERT_NEAR(yd[i], expected, kDoublePoleTol) << "double i=" << i;
                ASSERT_NEAR(yz[i], expected, kFloatPoleTol) << "-0, unnormalised i=" << i;
                if (l <= 4) {
                    ASSERT_NEAR(fixed[i], expected, kFloatPoleTol) << "fixed i=" << i;
                }
                // The textbook path at θ = 0 or π and any φ (φ is undefined there).
                for (double phi : {0.0, 1.0, -2.5, kPi})
                    ASSERT_NEAR(sh::evalShSlow(l, m, s > 0 ? 0.0 : kPi, phi), expected,
                                kDoublePoleTol)
                        << "slow i=" << i << " φ " << phi;
            }
        // Projection of a unit delta at the pole: the coefficients are Y_i(pole).
        sh::ShProjector p(kBand);
        p.add(glm::dvec3(pole), glm::dvec3(1.0));
        const auto c = p.coefficients();
        for (int l = 0; l <= kBand; ++l)
            for (int m = -l; m <= l; ++m)
                ASSERT_NEAR(c[sh::shIndex(l, m)], poleValue(l, m, s), kFloatPoleTol)
                    << "delta projection i=" << sh::shIndex(l, m);
    }
    // Projection of an equirect's polar rows (the pixels that touch θ = 0 and θ = π): a lit ring
    // of one row is zonal, so c_lm = 0 for m ≠ 0, and c_l0 = 2π ∫ Y_l0(θ) sin θ dθ over the row,
    // by 32-node Gauss–Legendre with Y from the textbook path.
    const int w = 16, h = 8;
    for (int row : {0, h - 1}) {
        std::vector<glm::vec3> rgb(std::size_t(w) * h, glm::vec3(0.f));
        for (int c = 0; c < w; ++c) rgb[std::size_t(row) * w + c] = glm::vec3(1.f);
        const auto c = sh::projectEquirect(kBand, {w, h, kPi, -2.0 * kPi / w}, rgb);
        const double t0 = kPi * row / h, t1 = kPi * (row + 1) / h;
        std::vector<double> x, wx;
        sh::gaussLegendre(32, x, wx);
        for (int l = 0; l <= kBand; ++l)
            for (int m = -l; m <= l; ++m) {
                double ring = 0.0;
                for (std::size_t q = 0; q < x.size(); ++q) {
                    const double theta = 0.5 * (t0 + t1) + 0.5 * (t1 - t0) * x[q];
                    ring += 0.5 * (t1 - t0) * wx[q] * std::sin(theta) *
                            sh::evalShSlow(l, 0, theta, 0.0);
                }
                const double expected = m == 0 ? 2.0 * kPi * ring : 0.0;
                ASSERT_NEAR(c[sh::shIndex(l, m)].x, expected, kCapTol)
                    << "row " << row << " l=" << l << " m=" << m;
            }
    }
}

TEST(HardCases, EnvironmentMapWithAHundredThousandToOneRange) {
    const TempDir tmp;
    const core::ImageRGBA map = sunAndSky();
    const auto mapPath = tmp / "sun.exr";
    io::writeImage(map, mapPath);
    // Through every method: finite, non-negative radiance (the SH reconstruction of a sun rings
    // negative around it; the shading must not pass that on as negative light).
    const auto volume = writeHard(kBall, tmp.path());
    for (const glm::dvec3& rot : {glm::dvec3(0.0), glm::dvec3(30, 90, 20)}) {
        const json lights = json::array({{{"type", "environment"},
                                          {"path", mapPath.string()},
                                          {"rotation", {rot.x, rot.y, rot.z}}}});
        EXPECT_EQ(renderEveryMethod(volume, lights, everyMethod(),
                                    "sun-and-sky rotation " + std::to_string(rot.y)),
                  int(allMethods().size()));
    }
    // The SH projection's DC is the map's integral: c_0 = Y_0 · Σ_p L_p Ω_p = Y_0 · 4π · (the
    // solid-angle-weighted mean of the map), independent of the rotation; and the whole band-8
    // projection equals the brute-force sum over rotated pixel centres.
    for (const glm::dvec3& rot : {glm::dvec3(0.0), glm::dvec3(30, 90, 20), glm::dvec3(0, -90, 0)}) {
        lights::EnvironmentOptions o;
        o.rotation = sceneRotation(rot);
        const lights::EnvironmentLight light(map, o, "sun");
        const auto c = light.shCoefficients({0, 0, 0}, kBand);
        const auto ref = bruteForceSh(map, light.rotation());
        long double integral = 0.0L;
        for (int r = 0; r < map.height; ++r) {
            const double t0 = kPi * r / map.height, t1 = kPi * (r + 1) / map.height;
            const long double omega = (2.0L * kPi / map.width) * (std::cos(t0) - std::cos(t1));
            for (int col = 0; col < map.width; ++col) integral += map.at(col, r)[0] * omega;
        }
        const double dcExpected = double(integral) * poleValue(0, 0, 1);
        EXPECT_NEAR(c[0].x, dcExpected, kDcRelTol * dcExpected) << "rotation y " << rot.y;
        for (std::size_t i = 0; i < c.size(); ++i) {
            ASSERT_TRUE(std::isfinite(c[i].x) && std::isfinite(c[i].y) && std::isfinite(c[i].z));
            ASSERT_NEAR(c[i].x, double(ref[i]), kFloatCoeffRelTol * dcExpected)
                << "rotation y " << rot.y << " i=" << i;
        }
        // Importance sampling of the sun: finite samples with a positive pdf that matches pdf().
        for (int k = 0; k < 64; ++k) {
            core::CounterRng rng(k, 5);
            const lights::LightSample s = light.sample({0, 0, 0}, {rng.uniform(), rng.uniform()});
            ASSERT_TRUE(std::isfinite(s.pdf) && s.pdf > 0.f) << s.pdf;
            ASSERT_TRUE(std::isfinite(s.value.x) && s.value.x >= 0.f) << s.value.x;
            EXPECT_NEAR(light.pdf({0, 0, 0}, s.wi), s.pdf, kPdfRelTol * s.pdf);
        }
    }
}
