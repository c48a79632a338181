// SPDX-License-Identifier: MIT
// The multiresolution block grid: exact at full budget, empty under a transparent TF, budgets
// respected, and no seams between blocks of different levels.
#include <gtest/gtest.h>

#include <cmath>

#include "core/rng.h"
#include "visibility/local_visibility.h"
#include "visibility/multires_grid.h"
#include "visibility/vis_test_util.h"

using namespace voxlight;
using namespace voxlight::visibility;

namespace {

/// Deterministic pseudo-random value in [lo, hi] for a voxel.
int noise(int i, int j, int k, int lo, int hi) {
    const std::uint64_t h =
        core::hashCounters(std::uint64_t(i), std::uint64_t(j), std::uint64_t(k), 7);
    return lo + int(h % std::uint64_t(hi - lo + 1));
}

/// Values of magnitude ≤ 1000: the product-form trilinear weights of the grid and the lerp chain
/// of core::VolumeView::sample round differently, by a few float ulps of the values (1000·2⁻²³
/// ≈ 1.2e-4 per ulp); 1e-3 allows 8 ulps.
constexpr float kRoundingTol = 1e-3f;

MultiresGrid gridWith(const core::Volume& v, const optics::TransferFunction& tf,
                      const LodBudget& budget) {
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    const optics::TfTable table(tf);
    return MultiresGrid(pyr, selectLod(*pyr, tf, table, budget));
}

}  // namespace

TEST(MultiresGrid, FullBudgetEqualsTheUnreducedGrid) {
    // Partial edge blocks on every axis (40 = 2·16 + 8, ...).
    const core::Volume v = test::makeVolume(
        {40, 35, 18}, [](int i, int j, int k) { return noise(i, j, k, 100, 900); });
    const MultiresGrid g = gridWith(v, test::rampTf(0.1f), LodBudget::unlimited());
    for (std::size_t b = 0; b < g.pyramid().blockCount(); ++b) ASSERT_EQ(g.level(b), 0) << b;
    // Level 0 holds the voxels bit for bit.
    for (std::size_t b = 0; b < g.pyramid().blockCount(); ++b) {
        const glm::ivec3 bc = g.pyramid().blockCoord(b);
        const float* d = g.pyramid().data(b, 0);
        for (int k = 0; k < kBlockSize; ++k)
            for (int j = 0; j < kBlockSize; ++j)
                for (int i = 0; i < kBlockSize; ++i) {
                    const glm::ivec3 x = bc * kBlockSize + glm::ivec3(i, j, k);
                    if (x.x >= 40 || x.y >= 35 || x.z >= 18) continue;
                    ASSERT_EQ(d[i + 16 * (j + 16 * k)], v.at(x.x, x.y, x.z)) << x.x << "," << x.y;
                }
    }
    // Sampling is trilinear interpolation of the voxels, block borders included.
    for (int n = 0; n < 4000; ++n) {
        const glm::vec3 p(core::toUnitFloat(core::hashCounters(n, 1, 0, 3)) * 39.f,
                          core::toUnitFloat(core::hashCounters(n, 2, 0, 3)) * 34.f,
                          core::toUnitFloat(core::hashCounters(n, 3, 0, 3)) * 17.f);
        ASSERT_NEAR(g.sample(p), v.sampleIndex(glm::dvec3(p)), kRoundingTol) << p.x << "," << p.y;
    }
    // Exactly on the block faces and corners too.
    for (float x : {15.f, 15.5f, 16.f, 31.25f, 32.f})
        for (float y : {15.f, 15.75f, 16.f})
            EXPECT_NEAR(g.sample({x, y, 15.5f}), v.sampleIndex({x, y, 15.5}), kRoundingTol);
}

TEST(MultiresGrid, FullyTransparentTfStoresNoBlock) {
    const core::Volume v = test::makeVolume(
        {32, 32, 32}, [](int i, int j, int k) { return noise(i, j, k, 100, 900); });
    const optics::TransferFunction clear(
        {{0.f, glm::vec3(1.f), 0.f, glm::vec3(0.f)}, {1000.f, glm::vec3(1.f), 0.f, glm::vec3(0.f)}},
        {500.f, 1000.f});
    const MultiresGrid g = gridWith(v, clear, LodBudget::unlimited());
    for (std::size_t b = 0; b < g.pyramid().blockCount(); ++b) EXPECT_EQ(g.level(b), kNone);
    EXPECT_EQ(g.selection().points, 0u);
    EXPECT_EQ(g.selection().blocksPerLevel[kLevels], g.pyramid().blockCount());
    EXPECT_EQ(g.sample({10.f, 10.f, 10.f}, -7.f), -7.f);  // the caller's empty value
}

TEST(MultiresGrid, SelectionRespectsTheBudgetAndGrowsWithIt) {
    // A sphere of "bone" in "tissue": blocks differ in significance.
    const core::Volume v = test::makeVolume({64, 64, 64}, [](int i, int j, int k) {
        const double r = std::hypot(i - 30.0, j - 33.0, k - 29.0);
        return (r < 18.0 ? 800 : 200) + noise(i, j, k, -40, 40);
    });
    const optics::TransferFunction tf({{0.f, glm::vec3(0.8f, 0.3f, 0.2f), 0.f, glm::vec3(0.f)},
                                       {500.f, glm::vec3(0.8f, 0.3f, 0.2f), 0.01f, glm::vec3(0.f)},
                                       {700.f, glm::vec3(1.f), 0.5f, glm::vec3(0.f)}},
                                      {350.f, 700.f});
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    const optics::TfTable table(tf);
    std::uint64_t previous = 0;
    for (double ratio : {4096.0, 512.0, 64.0, 16.0, 8.0, 4.0, 2.0, 1.0}) {
        const LodBudget budget = LodBudget::fromReduction(ratio, v.voxelCount());
        const LodSelection s = selectLod(*pyr, tf, table, budget);
        std::uint64_t points = 0;
        for (auto l : s.level)
            if (l != kNone) points += std::uint64_t(std::pow(levelResolution(l), 3));
        EXPECT_EQ(points, s.points);
        EXPECT_EQ(s.budgetPoints,
                  std::max<std::uint64_t>(budget.maxPoints, 64));  // 64 blocks at 1³
        EXPECT_LE(s.points, s.budgetPoints) << ratio;
        EXPECT_GE(s.points, previous) << ratio;
        previous = s.points;
    }
    EXPECT_EQ(previous, v.voxelCount());  // ratio 1: everything at 16³
    // At a tight budget the blocks holding the sphere's surface refine first.
    const LodSelection s =
        selectLod(*pyr, tf, table, LodBudget::fromReduction(16.0, v.voxelCount()));
    const std::size_t surface = pyr->blockIndex(2, 2, 2);  // voxels 32..47: crosses r = 18
    const std::size_t inside = pyr->blockIndex(1, 1, 1);   // voxels 16..31: all bone
    EXPECT_GT(s.significance[surface], s.significance[inside]);
    EXPECT_LT(s.level[surface], s.level[inside]);
}

TEST(MultiresGrid, ConstantBlocksHaveNoSignificance) {
    const core::Volume v = test::makeVolume(
        {32, 16, 16}, [](int i, int, int) { return i < 16 ? 600 : (i % 2 ? 100 : 900); });
    auto pyr = BlockPyramid::build(v);
    const optics::TransferFunction tf = test::rampTf(0.2f);
    const std::vector<float> s = blockSignificance(pyr, tf, optics::TfTable(tf));
    EXPECT_EQ(s[0], 0.f);
    EXPECT_GT(s[1], 1.f);  // ΔE units: alternating 100/900 against their mean is clearly visible
}

namespace {
/// Largest jump between successive samples of `f` along p0 + u·dir, u ∈ [0, len], steps of δ.
template <class F>
float largestJump(F&& f, glm::vec3 p0, glm::vec3 dir, float len, float delta) {
    float worst = 0.f, prev = f(p0);
    for (float u = delta; u <= len; u += delta) {
        const float v = f(p0 + u * dir);
        worst = std::max(worst, std::abs(v - prev));
        prev = v;
    }
    return worst;
}
}  // namespace

TEST(MultiresGrid, NoSeamsBetweenBlocksOfDifferentLevels) {
    // A smooth but non-linear field: each level's box means differ from the voxels.
    const core::Volume v = test::makeVolume({48, 48, 48}, [](int i, int j, int k) {
        return int(500 + 300 * std::sin(0.35 * i) * std::cos(0.21 * j) + 2 * k);
    });
    const optics::TransferFunction tf = test::rampTf(0.1f);
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    // Every block at a pseudo-random level, some not stored.
    LodSelection sel;
    sel.level.resize(pyr->blockCount());
    sel.significance.assign(pyr->blockCount(), 0.f);
    for (std::size_t b = 0; b < sel.level.size(); ++b)
        sel.level[b] = std::int8_t(core::hashCounters(b, 0, 0, 11) % kLevels);
    sel.level[pyr->blockIndex(1, 1, 1)] = 0;  // a 16³ block …
    sel.level[pyr->blockIndex(2, 1, 1)] = 3;  // … next to a 2³ block
    const MultiresGrid g(pyr, sel);
    // A cap on the step between successive samples δ apart: √3·R·(8·8 + 1)·δ with R ≤ 700 the
    // values' spread — the Lipschitz bound of the blend before 7 December (ramps rising ≤ 1 per
    // voxel, Σ ω ≥ 1/8), which the per-face ramps meet on this grid too; their own bound is
    // looser (Σ ω ≥ (1/17)³ in the worst corner), so the check that tells a seam is the next
    // one: a jump does not shrink with δ, a continuous blend's largest step shrinks ~10× when δ
    // does (checked with a factor-5 margin).
    constexpr float kDelta = 1e-3f;
    const float kSeamTol = std::sqrt(3.f) * 700.f * 65.f * kDelta;
    auto seamless = [&](const glm::vec3& p) { return g.sample(p); };
    auto continuous = [&](const glm::vec3& p0, const glm::vec3& dir, float len) {
        const float coarse = largestJump(seamless, p0, dir, len, kDelta);
        const float fine = largestJump(seamless, p0, dir, len, kDelta / 10.f);
        EXPECT_LE(coarse, kSeamTol);
        EXPECT_LE(fine, coarse / 5.f + 1e-3f);  // + float rounding of values ≤ 1000
    };
    // Across the face between the 16³ and the 2³ block (x = 31.5), at several heights.
    for (float y : {16.3f, 20.f, 24.9f, 31.2f}) continuous({24.f, y, 23.f}, {1.f, 0.f, 0.f}, 16.f);
    // Along random lines through the whole volume.
    for (int n = 0; n < 12; ++n) {
        const glm::vec3 p0(core::toUnitFloat(core::hashCounters(n, 1, 0, 5)) * 47.f, 0.f,
                           core::toUnitFloat(core::hashCounters(n, 2, 0, 5)) * 47.f);
        const glm::vec3 dir =
            glm::normalize(glm::vec3(core::toUnitFloat(core::hashCounters(n, 3, 0, 5)) - 0.5f, 1.f,
                                     core::toUnitFloat(core::hashCounters(n, 4, 0, 5)) - 0.5f));
        continuous(p0, dir, 47.f);
    }
    // The test can fail: sampling only the block that owns the point (clamped to its box) jumps.
    auto ownerOnly = [&](const glm::vec3& p) {
        const std::size_t b = g.ownerBlock(p);
        const int l = g.level(b);
        const float s = float(levelSpacing(l));
        glm::vec3 u = (p - glm::vec3(pyr->blockCoord(b) * kBlockSize) + 0.5f) / s - 0.5f;
        u = glm::clamp(u, glm::vec3(0.f), glm::vec3(float(levelResolution(l) - 1)));
        float out = 0.f;
        addTrilinear(pyr->data(b, l), levelResolution(l), 1, u, 1.f, &out);
        return out;
    };
    const float naive = largestJump(ownerOnly, {24.f, 20.f, 23.f}, {1.f, 0.f, 0.f}, 16.f, kDelta);
    EXPECT_GT(largestJump(ownerOnly, {24.f, 20.f, 23.f}, {1.f, 0.f, 0.f}, 16.f, kDelta / 10.f),
              naive / 2.f);  // a jump: it does not shrink with the step
    EXPECT_GT(naive, 5.f);
}

TEST(MultiresGrid, InsideItsSampleBoxABlockIsInterpolatedAlone) {
    const core::Volume v =
        test::makeVolume({32, 32, 32}, [](int i, int j, int k) { return noise(i, j, k, 0, 1000); });
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    LodSelection sel;
    sel.level = {2, 0, 4, 1, 0, 3, 2, 0};  // 2×2×2 blocks at mixed levels
    sel.significance.assign(8, 0.f);
    const MultiresGrid g(pyr, sel);
    // Block 0 at level 2 (4³, spacing 4): its box is [1.5, 13.5]³.
    BlockWeights w;
    g.weights({1.5f, 7.f, 13.5f}, w);
    ASSERT_EQ(w.count, 1);
    EXPECT_EQ(w.block[0], 0u);
    EXPECT_EQ(w.weight[0], 1.f);
    EXPECT_EQ(w.local[0], glm::vec3(0.f, 1.375f, 3.f));
    // Between block 0's last sample (x = 13.5) and block 1's first (level 0: x = 16) the two
    // blend linearly over the whole gap: no diagonal neighbour on either side is finer than the
    // other one across the face (block 7, level 0, lies diagonally past block 0's +x face, but
    // its limit (4 + 1)/2 equals the face's ramp), and block 4 (level 0), diagonal to block 1's
    // −x face, limits that ramp only toward z past block 1's box.
    for (float x : {14.9f, 15.7f}) {
        g.weights({x, 7.f, 7.f}, w);
        ASSERT_EQ(w.count, 2);
        const float w1 = w.block[0] == 1u ? w.weight[0] : w.weight[1];
        EXPECT_NEAR(w1, (x - 13.5f) / 2.5f, 1e-5f);
        EXPECT_NEAR(w.weight[0] + w.weight[1], 1.f, 1e-6f);
    }
}

// weights() visits only the candidate blocks its geometry allows (the owner's column per axis,
// the neighbour's where p is outside the owner's sample box on that axis or a diagonal block
// across it can reach in: MultiresGrid::reachesIn_): checked against
// the header's formula evaluated over every block of a mixed-level grid with unstored blocks, the
// ramp widths recomputed here from their definition.
TEST(MultiresGrid, WeightsAreTheHeaderFormulaOverEveryBlock) {
    const core::Volume v =
        test::makeVolume({48, 40, 36}, [](int i, int j, int k) { return noise(i, j, k, 0, 1000); });
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    const glm::ivec3 nb = pyr->blocks();
    LodSelection sel;
    sel.level.resize(pyr->blockCount());
    for (std::size_t b = 0; b < sel.level.size(); ++b) {
        const int r = int(core::hashCounters(b, 3, 0, 11) % 7);  // 0..4, two of seven unstored
        sel.level[b] = std::int8_t(r <= 4 ? r : kNone);
    }
    sel.significance.assign(sel.level.size(), 0.f);
    const MultiresGrid g(pyr, sel);
    auto spacing = [&](const glm::ivec3& c) {  // 0: outside the volume or not stored
        for (int a = 0; a < 3; ++a)
            if (c[a] < 0 || c[a] >= nb[a]) return 0.0;
        const int l = sel.level[pyr->blockIndex(c.x, c.y, c.z)];
        return l == kNone ? 0.0 : double(levelSpacing(l));
    };
    // The ramp length of block c toward side `side` of axis a at q (header comment, in double):
    // g toward the face neighbour, each diagonal neighbour n on that side shortening it toward
    // (s_c + s_n)/2 by t = Π over n's other axes of how far q lies past c's box toward n over
    // that length.
    auto rampLength = [&](const glm::ivec3& c, int a, int side, const glm::dvec3& q) {
        const double sc = spacing(c);
        glm::ivec3 f = c;
        f[a] += side;
        const double g = spacing(f) > 0.0 ? 0.5 * (sc + spacing(f)) : sc;
        double length = g;
        for (int d1 = -1; d1 <= 1; ++d1)
            for (int d2 = -1; d2 <= 1; ++d2) {
                if (d1 == 0 && d2 == 0) continue;
                glm::ivec3 n = f;
                const int a1 = (a + 1) % 3, a2 = (a + 2) % 3;
                n[a1] += d1;
                n[a2] += d2;
                if (spacing(n) == 0.0) continue;
                const double limit = 0.5 * (sc + spacing(n));
                double t = 1.0;
                for (auto [axis, dir] : {std::pair{a1, d1}, std::pair{a2, d2}}) {
                    if (dir == 0) continue;
                    const double lo = 16.0 * c[axis] + 0.5 * sc - 0.5;
                    const double hi = 16.0 * c[axis] + 16.0 - 0.5 * sc - 0.5;
                    const double past = dir > 0 ? q[axis] - hi : lo - q[axis];
                    t *= std::clamp(past / limit, 0.0, 1.0);
                }
                length = std::min(length, g + t * (limit - g));
            }
        return length;
    };
    std::size_t checked = 0, blended = 0;
    for (std::uint64_t n = 0; n < 20000; ++n) {
        glm::vec3 p;
        for (int a = 0; a < 3; ++a)
            p[a] = float(core::toUnitFloat(core::hashCounters(n, std::uint64_t(a), 0, 12)) *
                             (v.geometry().dims[a] + 1.0) -
                         1.0);  // a little past both ends too
        glm::dvec3 q;
        for (int a = 0; a < 3; ++a)
            q[a] = std::clamp(double(p[a]), 0.0, double(v.geometry().dims[a] - 1));
        std::vector<double> expected(pyr->blockCount(), 0.0);
        double sum = 0.0;
        for (int z = 0; z < nb.z; ++z)
            for (int y = 0; y < nb.y; ++y)
                for (int x = 0; x < nb.x; ++x) {
                    const std::size_t b = pyr->blockIndex(x, y, z);
                    if (sel.level[b] == kNone) continue;
                    double w = 1.0;
                    const glm::ivec3 c(x, y, z);
                    const double sc = spacing(c);
                    for (int a = 0; a < 3; ++a) {
                        const double lo = 16.0 * c[a] + 0.5 * sc - 0.5;  // the sample box
                        const double hi = 16.0 * c[a] + 16.0 - 0.5 * sc - 0.5;
                        if (q[a] > hi)
                            w *= std::max(0.0, 1.0 - (q[a] - hi) / rampLength(c, a, 1, q));
                        else if (q[a] < lo)
                            w *= std::max(0.0, 1.0 - (lo - q[a]) / rampLength(c, a, -1, q));
                    }
                    expected[b] = w;
                    sum += w;
                }
        BlockWeights got;
        g.weights(p, got);
        if (sum == 0.0) {
            EXPECT_EQ(got.count, 0) << "p = " << p.x << " " << p.y << " " << p.z;
            continue;
        }
        double gotSum = 0.0;
        for (int k = 0; k < got.count; ++k) {
            ASSERT_GT(expected[got.block[k]], 0.0)
                << "block " << got.block[k] << " at p = " << p.x << " " << p.y << " " << p.z;
            EXPECT_NEAR(got.weight[k], expected[got.block[k]] / sum, 1e-5);
            gotSum += expected[got.block[k]];
        }
        EXPECT_NEAR(gotSum, sum, 1e-9 * sum) << "a contributing block was left out";
        ++checked;
        blended += got.count > 1;
    }
    EXPECT_GT(checked, 10000u);
    EXPECT_GT(blended, 1000u);  // the test reaches the blending, not only block interiors
}

// The line sweep reads the voxels from one flat array kept with the pyramid: it must be the
// volume itself, x fastest — also past partial edge blocks (dims not multiples of 16), where the
// blocks repeat their edge voxel — counted in bytes() once made and shared by copies. Integer
// data in int16's range is held as int16 (2 bytes per voxel), anything else as float.
TEST(BlockPyramid, FlatVoxelsAreTheVolumeXFastestAndCountedOnceMade) {
    const glm::ivec3 dims(37, 18, 21);
    const core::Volume ints =
        test::makeVolume(dims, [](int i, int j, int k) { return noise(i, j, k, -1000, 3000); });
    // The same values plus a quarter where (i + j + k) is odd, as float: not integral.
    core::Volume fractions(ints.geometry(), core::VoxelType::Float32);
    // And float data that happens to be integral but beyond int16 (a 32-bit CT's 40000).
    core::Volume wide(ints.geometry(), core::VoxelType::Float32);
    for (int k = 0; k < dims.z; ++k)
        for (int j = 0; j < dims.y; ++j)
            for (int i = 0; i < dims.x; ++i) {
                const std::size_t at = ints.linearIndex(i, j, k);
                const float x = float(ints.dataAs<std::int16_t>()[at]);
                fractions.dataAs<float>()[at] = x + ((i + j + k) % 2 ? 0.25f : 0.f);
                wide.dataAs<float>()[at] = x + (i == 3 && j == 4 && k == 5 ? 40000.f : 0.f);
            }
    for (const auto& [v, compact] :
         {std::pair<const core::Volume*, bool>{&ints, true}, {&fractions, false}, {&wide, false}}) {
        const BlockPyramid pyr = BlockPyramid::build(*v);
        const std::size_t before = pyr.bytes();
        EXPECT_EQ(pyr.flatBytes(), 0u);
        const BlockPyramid copy = pyr;
        const BlockPyramid::FlatView flat = pyr.flatVoxels();
        ASSERT_EQ(flat.i != nullptr, compact);
        ASSERT_EQ(flat.f != nullptr, !compact);
        const std::size_t voxels = std::size_t(dims.x) * dims.y * dims.z;
        const std::size_t each = compact ? sizeof(std::int16_t) : sizeof(float);
        EXPECT_EQ(pyr.flatBytes(), voxels * each);
        EXPECT_EQ(pyr.bytes(), before + voxels * each);
        EXPECT_EQ(copy.flatVoxels().i, flat.i);  // made once, shared
        EXPECT_EQ(copy.flatVoxels().f, flat.f);
        std::size_t wrong = 0;
        for (int k = 0; k < dims.z; ++k)
            for (int j = 0; j < dims.y; ++j)
                for (int i = 0; i < dims.x; ++i)
                    wrong += flat[std::ptrdiff_t(i) +
                                  std::ptrdiff_t(dims.x) * (j + std::ptrdiff_t(dims.y) * k)] !=
                             v->at(i, j, k);
        EXPECT_EQ(wrong, 0u) << compact;
    }
}

TEST(MultiresGrid, VisibleCellBoxQueriesEqualTheScanOverTheBox) {
    // The summed-volume table behind visibilityNeeded (VisibleCellCounts, which the hierarchical
    // pyramid shares) against a scan of every cell in the box:
    // a sphere of visible matter in a transparent field (on a grid of 17×13×9 cells: not a power
    // of two, not a cube), points of every sample spacing anywhere in and just outside the volume.
    const core::Volume v = test::makeVolume({67, 50, 35}, [](int i, int j, int k) {
        return std::hypot(i - 40.0, j - 20.0, k - 15.0) < 9.0 ? 800 : 0;
    });
    const optics::TransferFunction tf({{0.f, glm::vec3(1.f), 0.f, glm::vec3(0.f)},
                                       {500.f, glm::vec3(1.f), 0.f, glm::vec3(0.f)},
                                       {700.f, glm::vec3(1.f), 0.5f, glm::vec3(0.f)}},
                                      {350.f, 700.f});
    const MultiresGrid grid = gridWith(v, tf, LodBudget::fromReduction(4.0, v.voxelCount()));
    const std::vector<std::uint8_t>& visible = grid.selection().cellVisible;
    std::size_t count = 0;
    for (auto c : visible) count += c;
    ASSERT_GT(count, 0u);
    ASSERT_LT(count, visible.size() / 4);
    core::CounterRng rng(core::hashCounters(3, 1, 4), 1);
    int needed = 0;
    for (int i = 0; i < 20000; ++i) {
        const glm::vec3 x(-3.f + 73.f * rng.uniform(), -3.f + 56.f * rng.uniform(),
                          -3.f + 41.f * rng.uniform());
        const float s = float(levelSpacing(i % 5));
        const bool fast = visibilityNeeded(grid, x, s);
        // The scan: every cell of the box within 2·s + 1 voxels of x.
        const glm::ivec3 cells = grid.pyramid().cells();
        const glm::ivec3 lo = glm::clamp(
            glm::ivec3(glm::floor((x - (2.f * s + 1.f)) / float(BlockPyramid::kCellVoxels))),
            glm::ivec3(0), cells - 1);
        const glm::ivec3 hi = glm::clamp(
            glm::ivec3(glm::floor((x + (2.f * s + 1.f)) / float(BlockPyramid::kCellVoxels))),
            glm::ivec3(0), cells - 1);
        bool scan = false;
        for (int cz = lo.z; cz <= hi.z; ++cz)
            for (int cy = lo.y; cy <= hi.y; ++cy)
                for (int cx = lo.x; cx <= hi.x; ++cx)
                    scan = scan || visible[std::size_t(cx) +
                                           std::size_t(cells.x) *
                                               (std::size_t(cy) + std::size_t(cells.y) * cz)] != 0;
        EXPECT_EQ(fast, scan) << x.x << ", " << x.y << ", " << x.z << " at spacing " << s;
        needed += fast;
    }
    EXPECT_GT(needed, 1000);
    EXPECT_LT(needed, 19000);
}

TEST(BlockPyramid, FloatDataNearItsLimitsBinsEveryVoxel) {
    // ±3e38: the histogram's hi − lo overflowed float, (val − lo)·0 was NaN and the bin index
    // negative — a crash of every SH method on such data (found by a hostile-input probe).
    core::Geometry g;
    g.dims = {16, 16, 16};
    core::Volume v(g, core::VoxelType::Float32);
    float* p = v.dataAs<float>();
    for (std::size_t i = 0; i < std::size_t(v.voxelCount()); ++i) p[i] = i % 2 ? 3e38f : -3e38f;
    const BlockPyramid pyr = BlockPyramid::build(v);
    const BlockStats& st = pyr.stats(0);
    std::uint64_t counted = 0;
    for (const std::uint32_t c : st.histogram) counted += c;
    EXPECT_EQ(counted, 4096u);
    EXPECT_EQ(st.histogram.front(), 2048u);
    EXPECT_EQ(st.histogram.back(), 2048u);
}
