// SPDX-License-Identifier: MIT
// PVRT basis lights (projection of distant lights, refusal of the others), the transfer grid's
// layout (which points are stored), and the radiance volume of a sphere against its closed form.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/error.h"
#include "lights/light.h"
#include "pathtrace/pathtrace_test_util.h"
#include "pvrt/basis.h"
#include "pvrt/direct.h"
#include "pvrt/radiance.h"
#include "pvrt/transfer.h"
#include "sh/sh_basis.h"

using namespace voxlight;

namespace {

/// Float sums of a few dozen terms.
constexpr double kSumTol = 1e-5;

TEST(PvrtBasis, SizesAndNames) {
    EXPECT_EQ(pvrt::Basis::sh(1).size(), 1);
    EXPECT_EQ(pvrt::Basis::sh(4).size(), 16);
    EXPECT_EQ(pvrt::Basis::sh(6).size(), 36);
    EXPECT_EQ(pvrt::Basis::sh(4).name(), "sh16");
    EXPECT_EQ(pvrt::Basis::dsf(162).size(), 162);
    EXPECT_EQ(pvrt::Basis::dsf(642).name(), "dsf642");
    EXPECT_THROW(pvrt::Basis::sh(0), InputError);
    EXPECT_THROW(pvrt::Basis::sh(7), InputError);
    EXPECT_THROW(pvrt::Basis::dsf(100), InputError);
}

TEST(PvrtBasis, ADirectionalLightProjectsToItsIrradiance) {
    const glm::vec3 e(2.f, 1.f, 0.5f);
    const glm::dvec3 dir = glm::normalize(glm::dvec3(0.3, -0.5, 0.8));
    std::vector<std::shared_ptr<const lights::Light>> ls{
        std::make_shared<lights::DirectionalLight>(e, glm::vec3(dir))};
    // SH: c_k = E·Y_k(ω_l).
    const auto basis = pvrt::Basis::sh(3);
    const auto c = basis.project(ls);
    ASSERT_EQ(int(c.size()), 9);
    int idx[36];
    float val[36];
    ASSERT_EQ(basis.evaluate(dir, idx, val), 9);
    for (int k = 0; k < 9; ++k) {
        EXPECT_EQ(idx[k], k);
        EXPECT_NEAR(c[std::size_t(k)].x, e.x * val[k], kSumTol);
        EXPECT_NEAR(c[std::size_t(k)].z, e.z * val[k], kSumTol);
    }
    // DSF: the power is kept, Σ A_k c_k = E, and only the directions near ω_l are lit.
    const auto dsf = pvrt::Basis::dsf(162);
    const auto s = dsf.project(ls);
    glm::dvec3 power(0.0);
    int lit = 0;
    for (int k = 0; k < 162; ++k) {
        power += dsf.dsf()->basisSolidAngles()[std::size_t(k)] * glm::dvec3(s[std::size_t(k)]);
        if (s[std::size_t(k)].x != 0.f) {
            ++lit;
            EXPECT_GT(glm::dot(dsf.dsf()->directions()[std::size_t(k)], dir), 0.9);
        }
    }
    EXPECT_NEAR(power.x, e.x, 1e-4);
    EXPECT_NEAR(power.y, e.y, 1e-4);
    EXPECT_LE(lit, 3);
    // DSF weights at a direction are a partition of unity.
    const int n = dsf.evaluate(dir, idx, val);
    double sum = 0;
    for (int i = 0; i < n; ++i) sum += val[i];
    EXPECT_NEAR(sum, 1.0, kSumTol);
}

TEST(PvrtBasis, PointLightsAreRefusedWithTheLightNamed) {
    std::vector<std::shared_ptr<const lights::Light>> ls{
        std::make_shared<lights::DirectionalLight>(glm::vec3(1.f), glm::vec3(0, 0, 1)),
        std::make_shared<lights::PointLight>(glm::vec3(1.f), glm::dvec3(0.0))};
    try {
        pvrt::Basis::sh(2).project(ls);
        FAIL() << "a point light was accepted";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "lights[1]");
        EXPECT_NE(e.problem().find("point"), std::string::npos);
    }
}

TEST(PvrtTransferLayout, StoresThePointsNearMatterOnly) {
    const auto m = test::makeMedium("sphere", test::stepTf(0.1f, glm::vec3(0.8f)), 32);
    const auto layout = pvrt::makeTransferLayout(*m.volume, *m.cells, 16);
    EXPECT_EQ(layout.res, glm::ivec3(16));
    EXPECT_EQ(layout.scale, glm::vec3(2.f));
    ASSERT_GT(layout.points, 0);
    // The centre is inside the sphere; the corners are far from it.
    EXPECT_GE(layout.slot[layout.linear({8, 8, 8})], 0);
    EXPECT_EQ(layout.slot[layout.linear({0, 0, 0})], -1);
    EXPECT_EQ(layout.slot[layout.linear({15, 15, 15})], -1);
    EXPECT_LT(layout.points, 16 * 16 * 16);
    // Stored indices run 0…points−1 in grid order.
    const auto pts = layout.storedPoints();
    ASSERT_EQ(int(pts.size()), layout.points);
    for (std::size_t i = 1; i < pts.size(); ++i)
        EXPECT_LT(layout.linear(pts[i - 1]), layout.linear(pts[i]));
    // Capped at the volume's size.
    EXPECT_EQ(pvrt::makeTransferLayout(*m.volume, *m.cells, 500).res, glm::ivec3(32));
    EXPECT_THROW(pvrt::makeTransferLayout(*m.volume, *m.cells, 0), InputError);
}

TEST(PvrtTransferLayout, AnEmptyVolumeStoresNothing) {
    const auto m = test::makeMedium("sphere", test::stepTf(0.f, glm::vec3(0.8f)), 16);
    const auto layout = pvrt::makeTransferLayout(*m.volume, *m.cells, 8);
    EXPECT_EQ(layout.points, 0);
    const pvrt::Transfer t(layout, 16);
    EXPECT_TRUE(t.values.empty());
}

}  // namespace

namespace {

TEST(PvrtRadiance, ASphereUnderADirectionalLightMatchesTheClosedForm) {
    // Direct part only, DSF 642 (holds a directional light within its kernel radius), transfer
    // at every voxel: S(x) = E·exp(−σ·d(x))/(4π), d = the distance from x to the sphere's surface
    // toward the light.
    constexpr float kSigma = 0.15f;
    const auto m = test::makeMedium("sphere", test::stepTf(kSigma, glm::vec3(0.9f)), 32);
    const auto facts = core::spherePhantomFacts(m.volume->geometry());
    const auto basis = pvrt::Basis::dsf(642);
    pvrt::Transfer t(pvrt::makeTransferLayout(*m.volume, *m.cells, 32), basis.size());
    pvrt::DirectOptions o;
    o.directions = 642;
    pvrt::addDirectTransfer(*m.volume, *m.table, basis, t, o);
    const glm::dvec3 l = glm::normalize(glm::dvec3(0.5, 0.6, -0.62));
    const float e = 6.f;
    std::vector<std::shared_ptr<const lights::Light>> ls{
        std::make_shared<lights::DirectionalLight>(glm::vec3(e), glm::vec3(l))};
    const auto r = pvrt::combineTransfer(t, basis.project(ls));
    double worst = 0;
    int n = 0;
    for (int z = 0; z < 32; z += 3)
        for (int y = 0; y < 32; y += 3)
            for (int x = 0; x < 32; x += 3) {
                const glm::dvec3 p = m.volume->geometry().indexToWorld(glm::dvec3(x, y, z));
                const glm::dvec3 q = p - facts.centre;
                const double b = glm::dot(q, l), c = glm::dot(q, q) - facts.radius * facts.radius;
                if (c > -4.0) continue;  // two voxels inside: away from the ramp of the surface
                const double d = -b + std::sqrt(b * b - c);
                const double want = e * std::exp(-kSigma * d) / (4.0 * std::numbers::pi);
                const double got = r.sample(glm::vec3(x, y, z)).x;
                worst = std::max(worst, std::abs(got - want) / want);
                ++n;
            }
    std::printf("sphere: %d points, worst relative error %.4f\n", n, worst);
    EXPECT_GT(n, 100);
    // The ramp of the surface (one voxel: value 0.5 at the radius) shifts the effective edge by
    // up to half a voxel: exp(0.15 · 0.5) − 1 = 8 %.
    constexpr double kSphereTol = 0.08;
    EXPECT_LT(worst, kSphereTol);
}

}  // namespace
