// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/phantoms.h"
#include "core/rng.h"
#include "optics/presets.h"
#include "optics/transfer_function.h"

using namespace voxlight;
using optics::TfPoint;
using optics::TransferFunction;

namespace {
TfPoint pt(float v, float sigma, glm::vec3 c = glm::vec3(0.5f), glm::vec3 e = glm::vec3(0.f)) {
    return {v, c, sigma, e};
}
/// A TF that steps from 0 to σ within 0.002 at 0.5 (sharp: the aliasing case).
TransferFunction stepTf(float sigma) {
    return TransferFunction({pt(0, 0, {1, 0, 0}), pt(0.499f, 0, {1, 0, 0}),
                             pt(0.501f, sigma, {0, 1, 0}), pt(1, sigma, {0, 1, 0})},
                            {0.5f, 1.f});
}
// Reference integrals by brute-force midpoint quadrature of the exact TF.
constexpr int kQuadratureSteps = 200000;
// Tolerances: the table has 4096 cells; its interpolation differs from the exact TF by < 1 cell at
// breakpoints, i.e. a relative error ≈ 1/4096 of the range on a step of unit height.
constexpr double kTableTol = 2e-3;
// σt·a is quadratic where both vary inside one table cell; the table interpolates it linearly, so a
// segment shorter than a cell inside a colour+opacity ramp sees up to ~1 % albedo error.
constexpr double kAlbedoTol = 1e-2;
}  // namespace

TEST(TransferFunction, PiecewiseLinearEvaluationAndClampedEnds) {
    const TransferFunction tf({pt(0, 0), pt(100, 1, {1, 1, 1}), pt(200, 3)}, {100, 200});
    EXPECT_FLOAT_EQ(tf.eval(-50).extinction, 0.f);
    EXPECT_FLOAT_EQ(tf.eval(50).extinction, 0.5f);
    EXPECT_FLOAT_EQ(tf.eval(150).extinction, 2.f);
    EXPECT_FLOAT_EQ(tf.eval(1e9f).extinction, 3.f);
    EXPECT_FLOAT_EQ(tf.eval(NAN).extinction, 0.f);  // NaN acts as the lowest value
    EXPECT_FLOAT_EQ(tf.maxExtinction(0, 120), 1.4f);
    EXPECT_FLOAT_EQ(tf.maxExtinction(10, 110), 1.2f);
    EXPECT_TRUE(tf.transparentOver(-100, 0));
    EXPECT_FALSE(tf.transparentOver(-100, 0.1f));
    EXPECT_NEAR(tf.surfaceValue(), 30.f, 1e-3);  // σt = 0.3 = max/10
}

TEST(TransferFunction, RejectsBadPointsWithTheField) {
    auto bad = [](std::vector<TfPoint> p) { TransferFunction t(std::move(p), {0, 1}); };
    EXPECT_THROW(bad({}), InputError);
    EXPECT_THROW(bad({pt(1, 0), pt(1, 0)}), InputError);  // not strictly increasing
    EXPECT_THROW(bad({pt(0, -1)}), InputError);
    EXPECT_THROW(bad({pt(0, NAN)}), InputError);
    EXPECT_THROW(bad({pt(0, 1, {2, 0, 0})}), InputError);
    try {
        bad({pt(5, 0), pt(3, 0)});
        FAIL();
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "points[1].value");
    }
}

TEST(TransferFunction, WindowLevelRemapsTheValueAxis) {
    const TransferFunction tf({pt(0, 0), pt(100, 1)}, {50, 100});
    const TransferFunction w = tf.withWindow({500, 200});
    EXPECT_FLOAT_EQ(w.points()[0].value, 400.f);
    EXPECT_FLOAT_EQ(w.points()[1].value, 600.f);
    EXPECT_FLOAT_EQ(w.eval(500).extinction, 0.5f);
    EXPECT_THROW(tf.withWindow({0, 0}), InputError);
    EXPECT_FLOAT_EQ(tf.scaledExtinction(3).eval(100).extinction, 3.f);
}

TEST(TfTable, LookupMatchesExactEvaluation) {
    const TransferFunction tf = optics::makePreset("ct-angio");
    const optics::TfTable table(tf);
    for (float v = -1100; v < 3200; v += 7.3f) {
        const auto a = tf.eval(v), b = table.lookup(v);
        EXPECT_NEAR(a.extinction, b.extinction, 6.f * 2.f * table.cellWidth() / 30.f) << v;
        EXPECT_NEAR(a.albedo.r, b.albedo.r, 0.02f) << v;
    }
    EXPECT_FLOAT_EQ(table.lookup(NAN).extinction, table.lookup(-1e9f).extinction);
    // The σt-only fast path is the same number, bit for bit, everywhere (clamps and NaN too).
    for (float v : {-1e9f, -1100.f, -3.7f, 0.f, 411.2f, 3199.f, 1e9f, float(NAN)})
        EXPECT_EQ(table.extinction(v), table.lookup(v).extinction) << v;
}

TEST(TfTable, MaxAndMinExtinctionAreTheExtremesOfExtinctionOverTheRangeExactly) {
    // The largest (smallest) extinction() over [lo, hi]: at the ends or at a table node between
    // them. A brute-force scan of every node against the sparse-table queries, over random ranges
    // of every width (one node, a few, the whole table, past both ends).
    const TransferFunction tf = optics::makePreset("ct-angio");
    const optics::TfTable table(tf);
    const float lo = tf.points().front().value, hi = tf.points().back().value;
    const float cell = table.cellWidth();
    core::CounterRng rng(17);
    for (int i = 0; i < 4000; ++i) {
        const float a = lo - 50.f + (hi - lo + 100.f) * rng.uniform();
        const float width = i % 4 == 0 ? cell * rng.uniform() * 3.f : (hi - lo) * rng.uniform();
        const float b = std::min(a + width, hi + 60.f);
        float brute = std::max(table.extinction(a), table.extinction(b));
        float bruteMin = std::min(table.extinction(a), table.extinction(b));
        for (int k = 0; k <= optics::TfTable::kTableCells; ++k) {
            const float v = lo + float(k) * cell;
            if (v > a && v < b) {
                brute = std::max(brute, table.extinction(v));
                bruteMin = std::min(bruteMin, table.extinction(v));
            }
        }
        EXPECT_EQ(table.maxExtinction(a, b), brute) << a << " … " << b;
        EXPECT_EQ(table.minExtinction(a, b), bruteMin) << a << " … " << b;
        const auto [least, most] = table.extinctionRange(a, b);
        EXPECT_EQ(least, bruteMin);
        EXPECT_EQ(most, brute);
    }
}

TEST(TfTable, PreintegratedSegmentIsTheExactMeanOverTheValueRange) {
    // For values varying linearly from sf to sb, mean σt = (1/(sb−sf)) ∫ σt(s) ds. Check against
    // brute-force quadrature of the exact TF, across a sharp step, both directions, and tails.
    const TransferFunction tf = stepTf(2.f);
    const optics::TfTable table(tf);
    const float pairs[][2] = {{0.2f, 0.9f}, {0.9f, 0.2f}, {0.45f, 0.55f}, {0.5f, 0.5001f},
                              {-3.f, 0.6f}, {0.8f, 4.f},  {0.1f, 0.3f}};
    for (const auto& p : pairs) {
        double sum = 0, sumG = 0;
        for (int i = 0; i < kQuadratureSteps; ++i) {
            const float s = p[0] + (p[1] - p[0]) * (float(i) + 0.5f) / kQuadratureSteps;
            const auto e = tf.eval(s);
            sum += e.extinction;
            sumG += e.extinction * e.albedo.g;
        }
        const double mean = sum / kQuadratureSteps;
        const auto seg = table.segment(p[0], p[1]);
        EXPECT_NEAR(seg.meanExtinction, mean, kTableTol * 2.0) << p[0] << " → " << p[1];
        if (mean > 0) {
            EXPECT_NEAR(seg.albedo.g, sumG / sum, kAlbedoTol) << p[0];
        }
    }
    // Transparent TF: nothing anywhere, no NaN.
    const optics::TfTable empty(TransferFunction({pt(0, 0), pt(1, 0)}, {0.5f, 1}));
    EXPECT_EQ(empty.segment(0.2f, 0.8f).meanExtinction, 0.f);
    EXPECT_EQ(empty.segment(NAN, 0.8f).meanExtinction, 0.f);
}

TEST(TfTable, FusedIntegralsGiveTheSameSegmentsAsTheCachedPath) {
    // The ray marcher's integrals() + segment(sf, a, sb, b) must agree with segment(sf, sb) (same
    // double arithmetic; only the order of a few operations differs) for every kind of pair:
    // inside the range, across the sharp step, tails on either side, tiny and zero differences,
    // NaN ends.
    constexpr double kFusedRelTol = 1e-5;  // float rounding of the result, not the method
    const TransferFunction tf = optics::makePreset("ct-bone");
    const optics::TfTable table(tf);
    ASSERT_FALSE(table.hasEmission());
    core::CounterRng rng(11);
    const float lo = table.lo() - 500.f, hi = table.hi() + 500.f;
    int checked = 0;
    for (int n = 0; n < 20000; ++n) {
        float a = lo + (hi - lo) * rng.uniform();
        float b = n % 5 == 0 ? a + (rng.uniform() - 0.5f) * 2.f : lo + (hi - lo) * rng.uniform();
        if (n % 97 == 0) b = a;
        if (n % 101 == 0) a = NAN;
        const auto ref = table.segment(a, b);
        const auto got = table.segment(a, table.integrals(a), b, table.integrals(b));
        const double tol = kFusedRelTol * std::max(1.0, double(ref.meanExtinction));
        ASSERT_NEAR(got.meanExtinction, ref.meanExtinction, tol) << a << " -> " << b;
        ASSERT_TRUE(std::isfinite(got.meanExtinction));
        if (ref.meanExtinction > 1e-3f) {
            for (int c = 0; c < 3; ++c)
                ASSERT_NEAR(got.albedo[c], ref.albedo[c], 1e-4) << a << " -> " << b;
        }
        checked += ref.meanExtinction > 0.f;
    }
    EXPECT_GT(checked, 5000) << "most pairs should see bone";
}

TEST(Presets, EveryPresetBuildsAndRelativeOnesFollowTheRange) {
    for (const auto& p : optics::presetCatalog()) {
        const TransferFunction tf = optics::makePreset(p.name, {100.f, 500.f});
        EXPECT_GT(tf.maxExtinction(), 0.f) << p.name;
        if (p.relative) {
            EXPECT_FLOAT_EQ(tf.window().level, 300.f) << p.name;
            EXPECT_FLOAT_EQ(tf.window().width, 400.f) << p.name;
            EXPECT_GE(tf.points().front().value, 99.f);
        }
    }
    EXPECT_THROW(optics::makePreset("ct-bones"), InputError);
    // CT bone: soft tissue (40 HU) transparent, cortical bone (1000 HU) opaque within a mm.
    const TransferFunction bone = optics::makePreset("ct-bone");
    EXPECT_EQ(bone.eval(40).extinction, 0.f);
    EXPECT_GT(1 - std::exp(-bone.eval(1000).extinction * 1.f), 0.9f);
    // CT angio: contrast lumen (300 HU) red, metal (3000 HU) grey-white.
    const TransferFunction angio = optics::makePreset("ct-angio");
    EXPECT_GT(angio.eval(300).albedo.r, 2 * angio.eval(300).albedo.g);
    EXPECT_GT(angio.eval(3000).albedo.b, 0.8f);
}

TEST(Presets, RobustRangeOfTheTorsoCoversAirToBone) {
    core::PhantomOptions o;
    o.size = 32;
    const core::Volume v = core::makePhantom("torso", o);
    const auto r = optics::robustRange(v);
    EXPECT_LT(r[0], -900.f);
    EXPECT_GT(r[1], 40.f);
    EXPECT_EQ(optics::defaultPresetName(v), "ct-bone");
}

TEST(Presets, ARangeOfAFewFloatStepsKeepsTheRelativePresetsPointsApart) {
    // A constant volume at 1e8 was refused (lo + 1 rounds to lo: a window of width 0); values one
    // float step apart (8 at 1e8) collapsed 'generic' onto one value. A range fewer than 64 float
    // steps wide becomes 64 steps; a constant one at least 1 wide; a narrow range of many steps
    // (0.05 at 1000: 819 steps) stays as it is.
    const auto range = [](float inside, float outside) {
        core::Volume v(core::Geometry{.dims = {8, 8, 8}}, core::VoxelType::Float32);
        float* d = v.dataAs<float>();
        for (int i = 0; i < 512; ++i) d[i] = (i % 8 >= 2 && i % 8 < 6) ? inside : outside;
        return optics::robustRange(v);
    };
    const float big = 1e8f, bigNext = std::nextafter(big, 2e8f);
    for (const auto& r : {range(big, big), range(bigNext, big)}) {
        EXPECT_EQ(r[0], big);
        EXPECT_FLOAT_EQ(r[1] - r[0], 64.f * (bigNext - big));
        const TransferFunction tf = optics::makePreset("generic", r);
        for (std::size_t k = 1; k < tf.points().size(); ++k)
            EXPECT_GT(tf.points()[k].value, tf.points()[k - 1].value) << k;
    }
    const auto flat = range(5.f, 5.f);
    EXPECT_EQ(flat[0], 5.f);
    EXPECT_EQ(flat[1], 6.f);
    const auto narrow = range(1000.05f, 1000.f);
    EXPECT_EQ(narrow[0], 1000.f);
    EXPECT_EQ(narrow[1], 1000.05f);
}

TEST(TfTable, ExtinctionChangeCoversEveryValueWhoseSigmaDiffers) {
    // Brute force: σt through the tables at 200 001 values from far below to far above the range;
    // every value where the two differ lies in the interval, and a colour-only edit gives none.
    const auto tf = [](float mid, float sigma, glm::vec3 c, float first) {
        return TransferFunction({{first, c, 0.f, glm::vec3(0.f)},
                                 {-100.f, c, 0.f, glm::vec3(0.f)},
                                 {mid, c, sigma, glm::vec3(0.f)},
                                 {900.f, c, 0.1f, glm::vec3(0.f)},
                                 {3000.f, c, 0.5f, glm::vec3(0.f)}},
                                {0.f, 1000.f});
    };
    const glm::vec3 grey(0.5f), red(1.f, 0.f, 0.f);
    struct Edit {
        TransferFunction before, after;
        bool none;
    };
    const std::vector<Edit> edits = {
        {tf(300.f, 0.05f, grey, -1000.f), tf(300.f, 0.2f, grey, -1000.f), false},   // σt at 300
        {tf(300.f, 0.05f, grey, -1000.f), tf(420.f, 0.05f, grey, -1000.f), false},  // point moved
        {tf(300.f, 0.05f, grey, -1000.f), tf(300.f, 0.05f, red, -1000.f), true},    // colour only
        {tf(300.f, 0.05f, grey, -1000.f), tf(300.f, 0.05f, grey, -1200.f), false},  // end moved
    };
    for (const Edit& e : edits) {
        const optics::TfTable a(e.before), b(e.after);
        const optics::ValueInterval changed =
            optics::extinctionChange(a.extinctionProfile(), b.extinctionProfile());
        EXPECT_EQ(changed.empty(), e.none);
        int differing = 0;
        for (int i = 0; i <= 200000; ++i) {
            const float v = -2000.f + 0.03f * float(i);
            if (a.extinction(v) != b.extinction(v)) {
                ++differing;
                EXPECT_TRUE(changed.meets(v, v)) << "σt differs at " << v << " outside ["
                                                 << changed.lo << ", " << changed.hi << "]";
            }
        }
        EXPECT_EQ(differing == 0, e.none);
        if (!e.none && std::isfinite(changed.lo)) {  // tight: within the edit's span ± 3 cells
            EXPECT_GT(changed.lo, -100.f - 3.f * a.cellWidth());
        }
    }
}

TEST(TransferFunction, SurfaceChannelsInterpolateLikeTheColours) {
    // Specular, roughness and phase g: piecewise linear between the points, constant beyond,
    // exactly as the albedo; the table's surface() agrees with the exact evaluation.
    std::vector<TfPoint> p = {pt(0, 0, {0, 0, 0}), pt(100, 1, {1, 1, 1}), pt(200, 3, {0, 1, 0})};
    p[0].specular = {0.f, 0.f, 0.f}, p[0].roughness = 1.f, p[0].phaseG = -0.2f;
    p[1].specular = {1.f, 0.5f, 0.f}, p[1].roughness = 0.2f, p[1].phaseG = 0.6f;
    p[2].specular = {0.f, 1.f, 0.f}, p[2].roughness = 0.5f, p[2].phaseG = 0.f;
    const TransferFunction tf(p, {100, 200});
    ASSERT_TRUE(tf.hasPhaseG());
    const optics::TfTable table(tf);
    ASSERT_TRUE(table.hasPhaseG());
    for (float v : {-50.f, 0.f, 25.f, 50.f, 100.f, 130.f, 199.f, 250.f}) {
        const optics::TfSample s = tf.eval(v);
        const optics::TfSurface u = tf.evalSurface(v);
        // The same weights as the albedo: red albedo 0→1 on [0, 100] like specular red.
        if (v <= 100.f) {
            EXPECT_NEAR(u.specular.r, s.albedo.r, 1e-6f) << v;
        }
        const float f = std::clamp(v / 100.f, 0.f, 1.f),
                    f2 = std::clamp((v - 100.f) / 100.f, 0.f, 1.f);
        const float rough = v <= 100.f ? 1.f + f * (0.2f - 1.f) : 0.2f + f2 * (0.5f - 0.2f);
        const float g = v <= 100.f ? -0.2f + f * 0.8f : 0.6f - f2 * 0.6f;
        EXPECT_NEAR(u.roughness, rough, 1e-6f) << v;
        EXPECT_NEAR(u.phaseG, g, 1e-6f) << v;
        const optics::TfSurface t = table.surface(v);
        EXPECT_NEAR(t.roughness, u.roughness, kTableTol) << v;
        EXPECT_NEAR(t.phaseG, u.phaseG, kTableTol) << v;
        EXPECT_NEAR(t.specular.g, u.specular.g, kTableTol) << v;
    }
    // Without the channels: specular 0, roughness 1, and no phase g (the method's applies).
    const TransferFunction plain({pt(0, 0), pt(1, 1)}, {0.5f, 1.f});
    EXPECT_FALSE(plain.hasPhaseG());
    EXPECT_FALSE(optics::TfTable(plain).hasPhaseG());
    EXPECT_TRUE(std::isnan(optics::TfTable(plain).surface(0.5f).phaseG));
    EXPECT_EQ(optics::TfTable(plain).surface(0.5f).roughness, 1.f);
}

TEST(TransferFunction, RejectsBadSurfaceChannelsWithTheField) {
    auto field = [](std::vector<TfPoint> p) {
        try {
            TransferFunction t(std::move(p), {0, 1});
        } catch (const InputError& e) {
            return e.field();
        }
        return std::string("accepted");
    };
    TfPoint a = pt(0, 1), b = pt(1, 1);
    a.roughness = 0.f;
    EXPECT_EQ(field({a, b}), "points[0].roughness");
    a = pt(0, 1), b.roughness = 1.5f;
    EXPECT_EQ(field({a, b}), "points[1].roughness");
    b = pt(1, 1), b.specular = {0.f, 1.2f, 0.f};
    EXPECT_EQ(field({a, b}), "points[1].specular");
    b = pt(1, 1), a.phaseG = 1.f, b.phaseG = 0.f;
    EXPECT_EQ(field({a, b}), "points[0].phase_g");
    a.phaseG = 0.5f, b.phaseG = optics::kNoPhaseG;
    EXPECT_EQ(field({a, b}), "points[1].phase_g");  // on some points but not all
    b.phaseG = -0.9f;
    EXPECT_EQ(field({a, b}), "accepted");
}

TEST(Presets, SurfaceChannelsAreSensibleAndCarryNoPhaseG) {
    // Bone matte with a low specular; the contrast lumen of ct-angio glossier than its bone.
    const optics::TfTable bone(optics::makePreset("ct-bone"));
    EXPECT_LE(bone.surface(1000.f).specular.r, 0.05f);
    EXPECT_GE(bone.surface(1000.f).roughness, 0.6f);
    const optics::TfTable angio(optics::makePreset("ct-angio"));
    EXPECT_LT(angio.surface(300.f).roughness, angio.surface(1000.f).roughness);
    EXPECT_GT(angio.surface(300.f).specular.r, angio.surface(1000.f).specular.r);
    for (const auto& info : optics::presetCatalog())
        EXPECT_FALSE(optics::makePreset(info.name, {0.f, 1.f}).hasPhaseG()) << info.name;
}

TEST(TfTable, BatchedIntegralsAndMeansAgreeWithTheScalarOnesWhereverAValueSitsInTheBatch) {
    // sigmaIntegrals / meanExtinctions (the line sweep's vectorised passes) against sigmaIntegral
    // and meanExtinction value by value — inside the table, in both transparent tails, past both
    // ends, across a cell, equal ends (point-sampled) — and each output a function of its own
    // inputs alone: the same batch shifted by 0…4 places (other lane, or the padded tail) gives
    // the same bits. Transparent segments give 0 exactly (the sweep counts on it).
    constexpr double kIntegralRelTol = 1e-12;  // double rounding, the formula's order only
    constexpr float kMeanRelTol = 1e-6f;       // the float result's rounding
    const TransferFunction tf = optics::makePreset("ct-bone");
    const optics::TfTable table(tf);
    ASSERT_GT(table.zeroBelow(), table.lo()) << "the case needs a lower transparent tail";
    core::CounterRng rng(23);
    const float lo = table.lo() - 300.f, hi = table.hi() + 300.f;
    std::vector<float> s;
    for (int i = 0; i < 4001; ++i) {
        const float prev = s.empty() ? 0.f : s.back();
        float v = lo + (hi - lo) * rng.uniform();
        if (i % 7 == 1) v = prev;                                      // equal ends
        if (i % 7 == 2) v = prev + 1e-3f * table.cellWidth();          // within a cell
        if (i % 7 == 3) v = table.zeroBelow() - 20.f * rng.uniform();  // lower tail
        if (i % 11 == 4) v = table.zeroBelow();                        // its end
        s.push_back(v);
    }
    const std::size_t n = s.size();
    std::vector<double> integrals(n);
    std::vector<float> means(n - 1);
    table.sigmaIntegrals(s.data(), n, integrals.data());
    table.meanExtinctions(s.data(), integrals.data(), n - 1, means.data());
    int transparent = 0, dense = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const double ref = table.sigmaIntegral(s[i]);
        ASSERT_NEAR(integrals[i], ref, kIntegralRelTol * std::max(1.0, std::abs(ref))) << s[i];
        if (i + 1 == n) break;
        const float mean = means[i];
        if (table.transparentSegment(s[i], s[i + 1])) {
            ASSERT_EQ(mean, 0.f) << s[i] << " -> " << s[i + 1];
            ++transparent;
            continue;
        }
        const float refMean =
            table.meanExtinction(s[i], ref, s[i + 1], table.sigmaIntegral(s[i + 1]));
        ASSERT_NEAR(mean, refMean, kMeanRelTol * std::max(1.f, refMean))
            << s[i] << " -> " << s[i + 1];
        dense += mean > 1.f;
    }
    EXPECT_GT(transparent, 500);
    EXPECT_GT(dense, 100) << "some segments should meet bone";
    for (std::size_t shift = 1; shift <= 4; ++shift) {
        std::vector<double> shifted(n - shift);
        std::vector<float> shiftedMeans(n - shift - 1);
        table.sigmaIntegrals(s.data() + shift, n - shift, shifted.data());
        table.meanExtinctions(s.data() + shift, shifted.data(), n - shift - 1, shiftedMeans.data());
        for (std::size_t i = 0; i + shift < n; ++i) {
            ASSERT_EQ(shifted[i], integrals[i + shift]) << "shift " << shift << ", value " << i;
            if (i + shift + 1 < n) ASSERT_EQ(shiftedMeans[i], means[i + shift]) << shift;
        }
    }
    // Batches of 1…7 values (all tail, no full lane of four) give the same bits too.
    for (std::size_t len = 1; len <= 7; ++len) {
        std::vector<double> part(len);
        table.sigmaIntegrals(s.data() + 100, len, part.data());
        for (std::size_t i = 0; i < len; ++i) ASSERT_EQ(part[i], integrals[100 + i]) << len;
    }
}
