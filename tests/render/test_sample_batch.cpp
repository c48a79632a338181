// SPDX-License-Identifier: MIT
// The marcher's eight-at-a-time sampling (AVX2 gathers) against its one-at-a-time form: the same
// lattice points, cells and values, for every integer voxel type, up to the grid's last voxel.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>

#include "core/rng.h"
#include "render/dvr_march.h"
#include "render_test_util.h"

namespace voxlight {
namespace {

#if defined(__AVX2__) && defined(__FMA__)

/// A volume of type T with pseudo-random values over the type's range, on an odd-sized grid so
/// that gathers reach the last bytes of the array.
template <class T>
core::Volume randomVolume(glm::ivec3 dims, std::uint64_t seed) {
    core::Geometry geom;
    geom.dims = dims;
    core::Volume v(geom, core::voxelTypeOf<T>());
    core::CounterRng rng(seed);
    T* d = v.dataAs<T>();
    for (std::uint64_t i = 0; i < v.voxelCount(); ++i) {
        const double lo = std::is_signed_v<T> ? -30000.0 : 0.0;
        const double hi = sizeof(T) == 1 ? 255.0 : (std::is_signed_v<T> ? 30000.0 : 65535.0);
        d[i] = T(lo + rng.uniform() * (hi - lo));
    }
    return v;
}

/// The marcher's sample position (DvrMarcher::at): fused multiply-adds, as the batch's lanes.
glm::vec3 at(const render::RaySegment& r, float t) {
    using render::detail::fmaF;
    return {fmaF(t, r.dirIndex.x, r.originIndex.x), fmaF(t, r.dirIndex.y, r.originIndex.y),
            fmaF(t, r.dirIndex.z, r.originIndex.z)};
}

template <class T>
void expectBatchEqualsScalar(const core::Volume& vol, const std::string& what) {
    using View = core::VolumeView<T>;
    const View view = vol.view<T>();
    const render::detail::CellSampler<View, true> sampler(view);
    using Batch = render::detail::SampleBatch<View, true>;
    ASSERT_TRUE(Batch::usable(sampler, vol.voxelCount())) << what;
    const glm::vec3 top = glm::vec3(vol.dims() - 1);
    core::CounterRng rng(11);
    // Transparent tails over the lower and upper 40 % of the values: about a third of the
    // segments are transparent.
    const float lo = std::is_signed_v<T> ? -30000.f : 0.f;
    const float hi = sizeof(T) == 1 ? 255.f : (std::is_signed_v<T> ? 30000.f : 65535.f);
    const float zeroBelow = lo + 0.4f * (hi - lo), zeroAbove = lo + 0.6f * (hi - lo);
    int lanes = 0, transparentLanes = 0;
    for (int n = 0; n < 300; ++n) {
        // A ray between two points of the grid's box (corners and faces included).
        glm::vec3 a(rng.uniform() * top.x, rng.uniform() * top.y, rng.uniform() * top.z);
        glm::vec3 b(rng.uniform() * top.x, rng.uniform() * top.y, rng.uniform() * top.z);
        if (n % 3 == 0) b = top;  // ends on the last voxel
        if (n % 5 == 0) a = glm::vec3(0.f);
        const float len = glm::length(b - a);
        if (!(len > 0.1f)) continue;
        render::RaySegment r;
        r.originIndex = a;
        r.dirIndex = (b - a) / len;
        r.tNear = 0.f;
        r.tFar = len;
        r.jitter = rng.uniform();
        const render::detail::SampleLattice lat(r, 0.37f + 0.5f * rng.uniform());
        for (std::int64_t i = 1; i <= lat.last; i += Batch::kLanes) {
            Batch batch;
            const float before = sampler.value(sampler.locate(at(r, lat.t(i - 1))));
            batch.take(i, lat, r, sampler, vol.voxelCount(), before, zeroBelow, zeroAbove);
            float prev = before;
            for (int l = 0; l < Batch::kLanes; ++l) {
                const float t = lat.t(i + l);
                const auto cell = sampler.locate(at(r, t));
                const float s = sampler.value(cell);
                ASSERT_EQ(batch.t[l], t) << what << " ray " << n << " sample " << i + l;
                const auto bc = batch.cell(l);
                ASSERT_EQ(bc.offset, cell.offset) << what << " ray " << n;
                ASSERT_EQ(bc.fx, cell.fx);
                ASSERT_EQ(bc.fy, cell.fy);
                ASSERT_EQ(bc.fz, cell.fz);
                ASSERT_EQ(bc.i, cell.i);
                ASSERT_EQ(bc.j, cell.j);
                ASSERT_EQ(bc.k, cell.k);
                ASSERT_EQ(batch.s[l], s) << what << " ray " << n << " sample " << i + l;
                const bool transparent =
                    std::max(prev, s) <= zeroBelow || std::min(prev, s) >= zeroAbove;
                ASSERT_EQ(bool(batch.transparent >> l & 1u), transparent) << what << " lane " << l;
                transparentLanes += transparent;
                prev = s;
                ++lanes;
            }
        }
    }
    EXPECT_GT(lanes, 2000) << what;
    EXPECT_GT(transparentLanes, 100) << what;
    EXPECT_LT(transparentLanes, lanes - 100) << what;
}

TEST(SampleBatch, EightAtATimeEqualsOneAtATime) {
    expectBatchEqualsScalar<std::uint8_t>(randomVolume<std::uint8_t>({13, 7, 5}, 1), "uint8");
    expectBatchEqualsScalar<std::int16_t>(randomVolume<std::int16_t>({9, 6, 5}, 2), "int16");
    expectBatchEqualsScalar<std::uint16_t>(randomVolume<std::uint16_t>({11, 3, 2}, 3), "uint16");
    // A one-row volume (ny = nz = 1: corner strides 0) of two voxels: 2 bytes < one gather word,
    // so it is not batched.
    core::Geometry tiny;
    tiny.dims = {2, 1, 1};
    const core::Volume two(tiny, core::VoxelType::UInt8);
    using View8 = core::VolumeView<std::uint8_t>;
    const render::detail::CellSampler<View8, true> s2(two.view<std::uint8_t>());
    EXPECT_FALSE((render::detail::SampleBatch<View8, true>::usable(s2, two.voxelCount())));
    expectBatchEqualsScalar<std::uint8_t>(randomVolume<std::uint8_t>({7, 1, 1}, 4), "one row");
}

#else
TEST(SampleBatch, EightAtATimeEqualsOneAtATime) {
    GTEST_SKIP() << "built without AVX2/FMA: the marcher samples one at a time";
}
#endif

}  // namespace
}  // namespace voxlight
