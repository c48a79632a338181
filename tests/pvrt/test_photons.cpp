// SPDX-License-Identifier: MIT
// PVRT's indirect transfer by volumetric photon mapping (pvrt/photons.h): exact zeros, thread
// independence, and the photons' kernel estimate against an independent backward Monte-Carlo
// estimate built from the path tracer's free flights and transmittances.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/error.h"
#include "core/phantoms.h"
#include "core/rng.h"
#include "pathtrace/pathtrace_test_util.h"
#include "pvrt/photons.h"

using namespace voxlight;

namespace {

constexpr double kPi = std::numbers::pi;

struct Scene {
    test::Medium medium;
    pathtrace::PathTracer tracer;
    pvrt::TransferLayout layout;
};

Scene makeScene(float sigma, glm::vec3 albedo, int size = 32, int resolution = 32) {
    test::Medium m = test::makeMedium("sphere", test::stepTf(sigma, albedo), size);
    pathtrace::PathTracer t = m.tracer();
    pvrt::TransferLayout l = pvrt::makeTransferLayout(*m.volume, *m.cells, resolution);
    return {std::move(m), std::move(t), std::move(l)};
}

/// The sphere phantom on anisotropic voxels (`spacing` mm) with its axes rotated in the world
/// (i → +y, j → +z, k → +x: a proper rotation), still centred on the world origin.
Scene makeTiltedScene(float sigma, glm::vec3 albedo, int size, glm::dvec3 spacing, int resolution) {
    auto v = std::make_shared<core::Volume>(
        core::makePhantom("sphere", {.size = size, .spacing = spacing}));
    core::Geometry& g = v->geometry();
    g.direction = glm::dmat3(glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1), glm::dvec3(1, 0, 0));
    g.origin = -(g.direction * (0.5 * glm::dvec3(g.dims - 1) * g.spacing));
    test::Medium m = test::makeMedium(v, test::stepTf(sigma, albedo));
    pathtrace::PathTracer t = m.tracer();
    pvrt::TransferLayout l = pvrt::makeTransferLayout(*m.volume, *m.cells, resolution);
    return {std::move(m), std::move(t), std::move(l)};
}

pvrt::Transfer run(const Scene& s, const pvrt::Basis& basis, const pvrt::PhotonOptions& o,
                   pvrt::PhotonStats* stats = nullptr) {
    pvrt::Transfer t(s.layout, basis.size());
    const pvrt::PhotonStats st =
        pvrt::addIndirectTransfer(s.tracer, basis, t, o, core::Progress::none());
    if (stats) *stats = st;
    return t;
}

/// The stored index of the grid point nearest to world point p (−1 when not stored).
std::int32_t slotNear(const Scene& s, const glm::dvec3& p) {
    const glm::vec3 v(s.medium.volume->geometry().worldToIndex(p));
    const glm::ivec3 g = glm::ivec3(glm::round(s.layout.gridCoordinate(v)));
    return s.layout.slot[s.layout.linear(g)];
}

glm::dvec3 pointWorld(const Scene& s, std::int32_t slot) {
    for (std::size_t i = 0; i < s.layout.slot.size(); ++i)
        if (s.layout.slot[i] == slot) {
            const glm::ivec3 r = s.layout.res;
            const glm::ivec3 g(int(i % r.x), int(i / r.x % r.y), int(i / (std::size_t(r.x) * r.y)));
            return s.medium.volume->geometry().indexToWorld(glm::dvec3(s.layout.position(g)));
        }
    return glm::dvec3(NAN);
}

glm::dvec3 uniformSphere(core::CounterRng& rng) {
    const double z = 1.0 - 2.0 * rng.uniformDouble(), r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = 2.0 * kPi * rng.uniformDouble();
    return {r * std::cos(phi), r * std::sin(phi), z};
}

/// Independent estimate of what the photons estimate at world point x: the indirect in-scattered
/// radiance S_ind,k (light scattered 1 … maxScatterings times) averaged over the poly6 kernel of
/// radius h around x, over the matter only (σt > 0; `matterOnly`, the collision estimator) or
/// over all the box (the track-length estimator) — exactly the expectation of the photons'
/// estimator, so the comparison has no kernel-blur bias, only noise.
/// Backward walk: y drawn from the kernel; S_ind(y) = E[L_ind(y, ω)] with ω uniform (isotropic
/// phase); delta tracking from y samples the next vertex z_j with pdf T·σt, which leaves the
/// weight a(z_j)·S(z_j); S(z_j)'s direct part (1/4π)∫T∞ B_k by one uniform direction ω' and a
/// ratio-tracked transmittance, B_k(ω')·T; its indirect part by continuing the walk.
/// Returns mean and standard error per (k, channel), [k·3 + c], and of Σ_k, [m·3 + c].
struct Estimate {
    std::vector<double> mean, stdErr;
};
Estimate reference(const Scene& s, const pvrt::Basis& basis, const glm::dvec3& x, double h,
                   int maxScatterings, int samples, std::uint64_t seed, bool matterOnly) {
    const int m = basis.size();
    // [k·3 + c], then Σ_k per channel at [m·3 + c].
    std::vector<double> sum(std::size_t(m + 1) * 3, 0.0), sum2(sum.size(), 0.0), one(sum.size());
    std::vector<int> idx(std::size_t(basis.maxSupport()));
    std::vector<float> val(idx.size());
    for (int n = 0; n < samples; ++n) {
        core::CounterRng rng(std::uint64_t(n), seed);
        std::fill(one.begin(), one.end(), 0.0);
        // y ~ poly6 kernel: uniform in the ball, accepted with probability (1 − r²/h²)³.
        glm::dvec3 y;
        while (true) {
            const glm::dvec3 u(2.0 * rng.uniformDouble() - 1.0, 2.0 * rng.uniformDouble() - 1.0,
                               2.0 * rng.uniformDouble() - 1.0);
            const double r2 = glm::dot(u, u);
            if (r2 >= 1.0) continue;
            const double w = 1.0 - r2;
            if (rng.uniformDouble() < w * w * w) {
                y = x + h * u;
                break;
            }
        }
        if (!matterOnly || s.tracer.extinctionAt(y) > 0.f) {
            glm::dvec3 pos = y, beta(1.0);
            for (int j = 1; j <= maxScatterings; ++j) {
                const pathtrace::Ray ray{pos, uniformSphere(rng)};
                double t0 = 0.0, t1 = INFINITY;
                if (!s.tracer.keptInterval(ray, t0, t1)) break;
                const auto t = s.tracer.freeFlight(ray, t0, t1, rng);
                if (!t) break;
                pos = ray.origin + *t * ray.direction;
                beta *= glm::dvec3(s.tracer.mediumAt(pos).albedo);
                // Direct light at this vertex: one uniform direction toward the light.
                const glm::dvec3 w = uniformSphere(rng);
                const double T = s.tracer.transmittance({pos, w}, INFINITY, rng);
                if (T > 0.0) {
                    const int cnt = basis.evaluate(w, idx.data(), val.data());
                    for (int i = 0; i < cnt; ++i)
                        for (int c = 0; c < 3; ++c)
                            one[std::size_t(idx[std::size_t(i)]) * 3 + c] +=
                                beta[c] * val[std::size_t(i)] * T;
                }
            }
        }
        for (int k = 0; k < m; ++k)
            for (int c = 0; c < 3; ++c) one[std::size_t(m) * 3 + c] += one[std::size_t(k) * 3 + c];
        for (std::size_t i = 0; i < one.size(); ++i) {
            sum[i] += one[i];
            sum2[i] += one[i] * one[i];
        }
    }
    Estimate e{std::vector<double>(sum.size()), std::vector<double>(sum.size())};
    for (std::size_t i = 0; i < sum.size(); ++i) {
        e.mean[i] = sum[i] / samples;
        const double var = std::max(0.0, sum2[i] / samples - e.mean[i] * e.mean[i]);
        e.stdErr[i] = std::sqrt(var / (samples - 1));
    }
    return e;
}

TEST(PvrtPhotons, AlbedoZeroAddsExactlyNothing) {
    const Scene s = makeScene(0.2f, glm::vec3(0.f));
    for (const pvrt::Estimator e : {pvrt::Estimator::Collision, pvrt::Estimator::TrackLength}) {
        pvrt::PhotonStats st;
        const auto t = run(s, pvrt::Basis::sh(2), {.photonsPerCell = 2, .estimator = e}, &st);
        ASSERT_GT(s.layout.points, 0);
        EXPECT_GT(st.collisions, 0u);
        EXPECT_EQ(st.splats, 0u);
        for (float v : t.values) ASSERT_EQ(v, 0.f);
    }
}

TEST(PvrtPhotons, ZeroDensityAddsNothingAndNoNaN) {
    // σt = 0 everywhere: no stored points from the layout; force every point stored to make sure
    // the photons cross the volume without collisions and write nothing.
    const Scene s0 = makeScene(0.f, glm::vec3(0.9f));
    Scene s = makeScene(0.f, glm::vec3(0.9f));
    s.layout.points = 0;
    for (auto& slot : s.layout.slot) slot = s.layout.points++;
    EXPECT_EQ(s0.layout.points, 0);
    for (const pvrt::Estimator e : {pvrt::Estimator::Collision, pvrt::Estimator::TrackLength}) {
        pvrt::PhotonStats st;
        const auto t = run(s, pvrt::Basis::sh(2), {.photonsPerCell = 1, .estimator = e}, &st);
        EXPECT_GT(st.photons, 0u);
        EXPECT_EQ(st.collisions, 0u);
        for (float v : t.values) ASSERT_EQ(v, 0.f);
    }
}

TEST(PvrtPhotons, SameTransferForAnyThreadCount) {
    // 12 photons per cell on the 32³ box: 69192 photons, two batches of kPhotonsPerBatch.
    const Scene s = makeScene(0.2f, glm::vec3(0.9f, 0.7f, 0.5f));
    const auto basis = pvrt::Basis::sh(2);
    for (const pvrt::Estimator e : {pvrt::Estimator::Collision, pvrt::Estimator::TrackLength}) {
        SCOPED_TRACE(e == pvrt::Estimator::Collision ? "collision" : "track-length");
        pvrt::PhotonStats st;
        const auto a = run(s, basis, {.photonsPerCell = 12, .estimator = e, .threads = 1}, &st);
        ASSERT_GT(std::int64_t(st.photons), pvrt::kPhotonsPerBatch);
        const auto b = run(s, basis, {.photonsPerCell = 12, .estimator = e, .threads = 2});
        const auto c = run(s, basis, {.photonsPerCell = 12, .estimator = e, .threads = 0});
        ASSERT_EQ(a.values.size(), b.values.size());
        EXPECT_TRUE(a.values == b.values);
        EXPECT_TRUE(a.values == c.values);
        // Another seed is another estimate.
        const auto d =
            run(s, basis, {.photonsPerCell = 12, .estimator = e, .seed = 2, .threads = 2});
        EXPECT_FALSE(a.values == d.values);
    }
}

TEST(PvrtPhotons, NegativeShFluxesStayFinite) {
    const Scene s = makeScene(0.25f, glm::vec3(0.85f));
    const auto t = run(s, pvrt::Basis::sh(4), {.photonsPerCell = 2});
    bool negative = false, positive = false;
    for (float v : t.values) {
        ASSERT_TRUE(std::isfinite(v));
        negative = negative || v < 0.f;
        positive = positive || v > 0.f;
    }
    EXPECT_TRUE(negative);
    EXPECT_TRUE(positive);
}

TEST(PvrtPhotons, RejectsBadOptions) {
    const Scene s = makeScene(0.2f, glm::vec3(0.9f));
    pvrt::Transfer t(s.layout, 1);
    const auto basis = pvrt::Basis::sh(1);
    EXPECT_THROW(pvrt::addIndirectTransfer(s.tracer, basis, t, {.photonsPerCell = 0},
                                           core::Progress::none()),
                 InputError);
    EXPECT_THROW(pvrt::addIndirectTransfer(s.tracer, basis, t, {.kernelRadiusCells = 0.f},
                                           core::Progress::none()),
                 InputError);
    EXPECT_THROW(pvrt::addIndirectTransfer(s.tracer, basis, t, {.maxScatterings = -1},
                                           core::Progress::none()),
                 InputError);
    EXPECT_THROW(pvrt::addIndirectTransfer(s.tracer, basis, t,
                                           {.estimator = static_cast<pvrt::Estimator>(7)},
                                           core::Progress::none()),
                 InputError);
}

TEST(PvrtPhotons, CancellationThrows) {
    const Scene s = makeScene(0.2f, glm::vec3(0.9f));
    pvrt::Transfer t(s.layout, 1);
    std::atomic<bool> cancel{true};
    const core::Progress p([](const std::string&, double) {}, &cancel);
    EXPECT_THROW(pvrt::addIndirectTransfer(s.tracer, pvrt::Basis::sh(1), t, {}, p), CancelledError);
}

/// Photon estimates from independent seeds (their spread is the photons' noise) against the
/// backward reference at the grid points nearest to `at` (world mm). Fails when any (k, channel)
/// differs by more than kMaxZ combined standard errors; prints the table then.
void expectMatchesReference(const Scene& s, const pvrt::Basis& basis, pvrt::PhotonOptions o,
                            int seeds, const std::vector<glm::dvec3>& at, int refSamples,
                            double maxZ) {
    const int m = basis.size();
    const auto& geo = s.medium.volume->geometry();
    const double h =
        o.kernelRadiusCells * double(glm::max(glm::max(s.layout.scale.x * geo.spacing.x,
                                                       s.layout.scale.y * geo.spacing.y),
                                              s.layout.scale.z * geo.spacing.z));
    std::vector<pvrt::Transfer> runs;
    for (int r = 0; r < seeds; ++r) {
        o.seed = std::uint64_t(101 + r);
        runs.push_back(run(s, basis, o));
    }
    for (std::size_t p = 0; p < at.size(); ++p) {
        const std::int32_t slot = slotNear(s, at[p]);
        ASSERT_GE(slot, 0);
        const glm::dvec3 x = pointWorld(s, slot);
        const Estimate ref = reference(s, basis, x, h, o.maxScatterings, refSamples, 7 + p,
                                       o.estimator == pvrt::Estimator::Collision);
        std::string table;
        double worst = 0.0;
        // Each basis light, and their sum (k = m: less noisy, so more sensitive).
        for (int k = 0; k <= m; ++k)
            for (int c = 0; c < 3; ++c) {
                const std::size_t i = std::size_t(k) * 3 + c;
                auto value = [&](const pvrt::Transfer& t) {
                    if (k < m) return double(t.row(slot)[i]);
                    double v = 0.0;
                    for (int j = 0; j < m; ++j) v += t.row(slot)[std::size_t(j) * 3 + c];
                    return v;
                };
                double mean = 0.0, sq = 0.0;
                for (const auto& t : runs) mean += value(t);
                mean /= seeds;
                for (const auto& t : runs) sq += (value(t) - mean) * (value(t) - mean);
                const double se = std::sqrt(sq / (seeds - 1) / seeds);
                const double z =
                    (mean - ref.mean[i]) / std::sqrt(se * se + ref.stdErr[i] * ref.stdErr[i]);
                worst = std::max(worst, std::abs(z));
                char line[160];
                std::snprintf(line, sizeof line,
                              "  k=%d c=%d photons %.5f ± %.5f reference %.5f ± %.5f z=%.2f\n", k,
                              c, mean, se, ref.mean[i], ref.stdErr[i], z);
                table += line;
            }
        EXPECT_LE(worst, maxZ) << "at (" << x.x << ", " << x.y << ", " << x.z << ") mm\n" << table;
    }
}

/// The photons' noise is estimated from 16 seeds (Student t, 15 degrees of freedom) and the
/// reference's from its samples; with ~50 comparisons per test, |z| ≤ 5 is passed by an unbiased
/// estimator except with probability ~1e-3 (the seeds are fixed, so it is decided once). The
/// tests use a kernel of 4 grid steps (the reference is blurred by the same kernel, so a wide one
/// costs no bias and cuts the noise): the constant basis light's mean then has ~1.2% noise,
/// so an error of ~7% or more fails (z > 5); the measured |z| were all below 2.2.
constexpr double kMaxZ = 5.0;
constexpr int kSeeds = 16;

/// The reference tests run for each estimator (the reference integrates over the matter only
/// for the collision estimator, over the whole box for the track-length one). The track-length
/// estimator costs ~5× more per photon with a kernel of 4 grid steps and has a fraction of the
/// noise, so it gets a quarter of the photons where that keeps the test fast.
int photonsFor(pvrt::Estimator e, int collisionPhotons) {
    return e == pvrt::Estimator::TrackLength ? collisionPhotons / 4 : collisionPhotons;
}
class PvrtPhotonsEstimator : public testing::TestWithParam<pvrt::Estimator> {};

INSTANTIATE_TEST_SUITE_P(Estimators, PvrtPhotonsEstimator,
                         testing::Values(pvrt::Estimator::Collision, pvrt::Estimator::TrackLength),
                         [](const testing::TestParamInfo<pvrt::Estimator>& info) {
                             return info.param == pvrt::Estimator::Collision ? "Collision"
                                                                             : "TrackLength";
                         });

TEST_P(PvrtPhotonsEstimator, MatchesABackwardMonteCarloEstimateInASphere) {
    // Homogeneous sphere, radius ≈ 10.9 mm, σt·radius ≈ 1.6, coloured albedo; SH order 2 (a
    // constant and three linear basis lights, negative over half the sphere of directions).
    const Scene s = makeScene(0.15f, glm::vec3(0.9f, 0.8f, 0.6f));
    expectMatchesReference(s, pvrt::Basis::sh(2),
                           {.photonsPerCell = photonsFor(GetParam(), 32),
                            .kernelRadiusCells = 4.f,
                            .maxScatterings = 3,
                            .rouletteAfter = 1,
                            .estimator = GetParam()},
                           kSeeds,
                           {glm::dvec3(0.0), glm::dvec3(5.0, 0.0, 0.0), glm::dvec3(0.0, -3.0, 6.0),
                            glm::dvec3(-8.0, 2.0, 0.0)},
                           100000, kMaxZ);
}

TEST_P(PvrtPhotonsEstimator, FurnaceStaysBelowTheInfiniteMediumBound) {
    // A uniform environment of radiance L = Y_00 (SH order 1) around a sphere (σt·radius ≈ 3.3)
    // of albedo 0.99: the radiance inside never exceeds L (the medium only removes and
    // redistributes it), so neither does the in-scattered S = (1/4π)∫L dω, nor its indirect
    // part. Long paths (up to 200 scatterings, with roulette) must neither blow up nor vanish.
    const Scene s = makeScene(0.3f, glm::vec3(0.99f));
    const auto basis = pvrt::Basis::sh(1);
    const double L = 0.5 / std::sqrt(kPi);
    const pvrt::PhotonOptions o{.photonsPerCell = photonsFor(GetParam(), 32),
                                .maxScatterings = 200,
                                .estimator = GetParam()};
    const auto t = run(s, basis, o);
    // Positive fluxes: every value ≥ 0; the mean over the central ball (radius 4 mm, ~250
    // points: noise ~1%) below L.
    double sum = 0.0;
    int n = 0;
    for (const glm::ivec3& g : s.layout.storedPoints()) {
        const float v = t.row(s.layout.slot[s.layout.linear(g)])[0];
        ASSERT_TRUE(std::isfinite(v));
        ASSERT_GE(v, 0.f);
        const glm::dvec3 x =
            s.medium.volume->geometry().indexToWorld(glm::dvec3(s.layout.position(g)));
        if (glm::length(x) < 4.0) sum += v, ++n;
    }
    ASSERT_GT(n, 100);
    EXPECT_LT(sum / n, L);
    // And the centre against the reference with the same long paths.
    expectMatchesReference(s, basis,
                           {.photonsPerCell = photonsFor(GetParam(), 8),
                            .kernelRadiusCells = 4.f,
                            .maxScatterings = 200,
                            .estimator = GetParam()},
                           kSeeds, {glm::dvec3(0.0), glm::dvec3(0.0, 0.0, 8.0)}, 100000, kMaxZ);
}

TEST_P(PvrtPhotonsEstimator, MatchesTheReferenceOnAnisotropicRotatedVoxelsWithADsfBasis) {
    // 28 voxels of 1 × 1 × 1.6 mm, axes rotated in the world, transfer grid 14³ (2 voxels per
    // step: grid steps 2, 2, 3.2 mm), DSF 42: the kernel's world distances, the boundary cells'
    // areas and normals, and the sparse basis all enter.
    const Scene s =
        makeTiltedScene(0.15f, glm::vec3(0.85f, 0.7f, 0.5f), 28, glm::dvec3(1.0, 1.0, 1.6), 14);
    expectMatchesReference(s, pvrt::Basis::dsf(42),
                           {.photonsPerCell = 32,
                            .kernelRadiusCells = 2.f,
                            .maxScatterings = 2,
                            .rouletteAfter = 1,
                            .estimator = GetParam()},
                           kSeeds, {glm::dvec3(0.0), glm::dvec3(3.0, -4.0, 2.0)}, 100000, kMaxZ);
}

TEST(PvrtPhotons, TrackLengthAgreesWithTheCollisionEstimatorWithLessNoise) {
    // Thin homogeneous sphere (radius ≈ 10.9 mm, σt·radius ≈ 0.8: a photon collides about once),
    // SH order 2, 16 seeds of each estimator at equal photons. At the stored points whose kernel
    // lies in the matter (≥ h inside the sphere) both estimate the same (1/4π)∫W φ_ind: their
    // seed means, summed over the points of each octant and over all of them (per basis light
    // and channel: 9 × 12 sums, each over hundreds of points, so nearly normal), must agree
    // within kMaxZ combined standard errors. The track-length estimator's variance across seeds,
    // summed over those points, must be well below the collision estimator's.
    const Scene s = makeScene(0.075f, glm::vec3(0.9f, 0.8f, 0.6f));
    const auto basis = pvrt::Basis::sh(2);
    const int m = basis.size();
    const pvrt::PhotonOptions base{
        .photonsPerCell = 8, .kernelRadiusCells = 2.f, .maxScatterings = 4, .rouletteAfter = 1};
    const auto& geo = s.medium.volume->geometry();
    const double h = base.kernelRadiusCells * double(s.layout.scale.x) * geo.spacing.x;
    // The sphere phantom's radius: 0.35 of the box (about 10.9 mm here); keep 1 mm of margin.
    const double inner = 0.35 * 31.0 * geo.spacing.x - h - 1.0;
    std::vector<std::int32_t> slots;
    std::vector<int> octant;
    for (const glm::ivec3& g : s.layout.storedPoints()) {
        const glm::dvec3 x = geo.indexToWorld(glm::dvec3(s.layout.position(g)));
        if (glm::length(x) >= inner) continue;
        slots.push_back(s.layout.slot[s.layout.linear(g)]);
        octant.push_back((x.x > 0) + 2 * (x.y > 0) + 4 * (x.z > 0));
    }
    ASSERT_GT(slots.size(), 1000u);
    const std::size_t dim = std::size_t(m) * 3;
    constexpr std::size_t kGroups = 9;  // the eight octants, then all points
    // Per estimator: per (point, value) the seed mean and variance, and per (group, value) the
    // sum over the group's points' seed mean and variance.
    struct Moments {
        std::vector<double> mean, var, sumMean, sumVar;
    };
    auto moments = [&](pvrt::Estimator e) {
        Moments r{std::vector<double>(slots.size() * dim, 0.0),
                  std::vector<double>(slots.size() * dim, 0.0),
                  std::vector<double>(kGroups * dim, 0.0), std::vector<double>(kGroups * dim, 0.0)};
        std::vector<double> sq(r.mean.size(), 0.0), sumSq(kGroups * dim, 0.0);
        for (int seed = 0; seed < kSeeds; ++seed) {
            pvrt::PhotonOptions o = base;
            o.estimator = e;
            o.seed = std::uint64_t(301 + seed);
            const pvrt::Transfer t = run(s, basis, o);
            std::vector<double> total(kGroups * dim, 0.0);
            for (std::size_t p = 0; p < slots.size(); ++p)
                for (std::size_t i = 0; i < dim; ++i) {
                    const double v = t.row(slots[p])[i];
                    r.mean[p * dim + i] += v;
                    sq[p * dim + i] += v * v;
                    total[std::size_t(octant[p]) * dim + i] += v;
                    total[(kGroups - 1) * dim + i] += v;
                }
            for (std::size_t i = 0; i < total.size(); ++i) {
                r.sumMean[i] += total[i];
                sumSq[i] += total[i] * total[i];
            }
        }
        auto finish = [](double& mean, double& var, double sq2) {
            mean /= kSeeds;
            var = std::max(0.0, (sq2 - kSeeds * mean * mean) / (kSeeds - 1));
        };
        for (std::size_t i = 0; i < r.mean.size(); ++i) finish(r.mean[i], r.var[i], sq[i]);
        for (std::size_t i = 0; i < r.sumMean.size(); ++i)
            finish(r.sumMean[i], r.sumVar[i], sumSq[i]);
        return r;
    };
    const Moments col = moments(pvrt::Estimator::Collision);
    const Moments trk = moments(pvrt::Estimator::TrackLength);
    auto z = [](double ma, double va, double mb, double vb) {
        const double se = std::sqrt((va + vb) / kSeeds);
        return se > 0.0 ? (ma - mb) / se : 0.0;
    };
    double worst = 0.0;
    for (std::size_t i = 0; i < col.sumMean.size(); ++i) {
        const double zi = z(trk.sumMean[i], trk.sumVar[i], col.sumMean[i], col.sumVar[i]);
        worst = std::max(worst, std::abs(zi));
        EXPECT_LE(std::abs(zi), kMaxZ)
            << "group " << i / dim << " value " << i % dim << ": track-length " << trk.sumMean[i]
            << " collision " << col.sumMean[i];
    }
    double colVar = 0.0, trkVar = 0.0;
    for (std::size_t i = 0; i < col.var.size(); ++i) {
        colVar += col.var[i];
        trkVar += trk.var[i];
    }
    std::printf(
        "%zu points inside: worst |z| of the group sums %.2f; summed per-point variance "
        "across seeds: track-length / collision = %.3f\n",
        slots.size(), worst, trkVar / colVar);
    EXPECT_LT(trkVar, 0.5 * colVar);
}

}  // namespace

TEST(PvrtPhotons, ExitanceCoefficientZeroIsTheIsotropicTransferBitForBit) {
    // n = 4: coefficient 0 of every row is the n = 1 transfer exactly (Ŷ_0 = 1, same photons);
    // the band-1 coefficients carry the direction the light arrives from, so they are not zero.
    const Scene s = makeScene(0.15f, glm::vec3(0.9f), 16, 16);
    const pvrt::Basis basis = pvrt::Basis::sh(2);
    for (pvrt::Estimator e : {pvrt::Estimator::Collision, pvrt::Estimator::TrackLength}) {
        const pvrt::PhotonOptions o{.photonsPerCell = 4, .estimator = e};
        const pvrt::Transfer iso = run(s, basis, o);
        pvrt::Transfer t4(s.layout, basis.size(), 4);
        pvrt::addIndirectTransfer(s.tracer, basis, t4, o, core::Progress::none());
        const std::size_t m3 = std::size_t(basis.size()) * 3;
        double band1 = 0.0;
        for (std::int32_t p = 0; p < s.layout.points; ++p) {
            for (std::size_t i = 0; i < m3; ++i) ASSERT_EQ(t4.row(p)[i], iso.row(p)[i]) << p;
            for (std::size_t i = m3; i < 4 * m3; ++i) band1 += std::abs(t4.row(p)[i]);
        }
        EXPECT_GT(band1, 0.0);
    }
}

TEST(PvrtPhotons, PhaseGOutsideTheOpenIntervalIsRefusedByName) {
    const Scene s = makeScene(0.15f, glm::vec3(0.9f), 16, 16);
    const pvrt::Basis basis = pvrt::Basis::sh(1);
    for (float g : {1.f, -1.f, NAN}) {
        pvrt::Transfer t(s.layout, 1, 4);
        try {
            pvrt::addIndirectTransfer(s.tracer, basis, t, {.phaseG = g}, core::Progress::none());
            ADD_FAILURE() << "accepted g " << g;
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), "phase_g");
        }
    }
}
