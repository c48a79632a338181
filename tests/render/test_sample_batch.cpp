// SPDX-License-Identifier: MIT
// The marcher's eight-at-a-time sampling (AVX2 gathers) against its one-at-a-time form: the same
// lattice points, cells and values, for every integer voxel type, up to the grid's last voxel.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>

#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#endif

#include "core/rng.h"
#include "render/dvr_march.h"
#include "render_test_util.h"

namespace voxlight {
namespace {

#if defined(__AVX2__) && defined(__FMA__)

/// A volume of type T with pseudo-random values over the type's range, on an odd-sized grid so
/// that gathers reach the last bytes of the array. On Linux the voxels end exactly where an
/// inaccessible page begins, so that a gather reading past the volume crashes the test.
template <class T>
core::Volume randomVolume(glm::ivec3 dims, std::uint64_t seed) {
    core::Geometry geom;
    geom.dims = dims;
    const std::size_t bytes = std::size_t(dims.x) * dims.y * dims.z * sizeof(T);
#if defined(__linux__)
    const std::size_t page = std::size_t(sysconf(_SC_PAGESIZE));
    const std::size_t pages = (bytes + page - 1) / page + 1;
    void* base =
        mmap(nullptr, pages * page, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    EXPECT_NE(base, MAP_FAILED);
    EXPECT_EQ(mprotect(static_cast<char*>(base) + (pages - 1) * page, page, PROT_NONE), 0);
    std::shared_ptr<std::byte> storage(
        reinterpret_cast<std::byte*>(static_cast<char*>(base) + (pages - 1) * page - bytes),
        [base, len = pages * page](std::byte*) { munmap(base, len); });
    core::Volume v(geom, core::voxelTypeOf<T>(), storage);
#else
    core::Volume v(geom, core::voxelTypeOf<T>());
#endif
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
    // Transparent tails over the lower and upper 40 % of the (physical) values: about a third
    // of the segments are transparent.
    const float slope = float(vol.mapping.slope), intercept = float(vol.mapping.intercept);
    const float lo = slope * (std::is_signed_v<T> ? -30000.f : 0.f) + intercept;
    const float hi =
        slope * (sizeof(T) == 1 ? 255.f : (std::is_signed_v<T> ? 30000.f : 65535.f)) + intercept;
    const float zeroBelow = lo + 0.4f * (hi - lo), zeroAbove = lo + 0.6f * (hi - lo);
    int lanes = 0, transparentLanes = 0;
    for (int n = 0; n < 300; ++n) {
        // A ray between two points around the grid's box (outside it too, where locate()
        // clamps; corners and faces included), starting at a t other than 0.
        auto point = [&] {
            return glm::vec3(rng.uniform(), rng.uniform(), rng.uniform()) * (top + 4.f) - 2.f;
        };
        glm::vec3 a = point(), b = point();
        if (n % 3 == 0) b = top;  // ends on the last voxel
        if (n % 5 == 0) a = glm::vec3(0.f);
        const float len = glm::length(b - a);
        if (!(len > 0.1f)) continue;
        render::RaySegment r;
        r.dirIndex = (b - a) / len;
        r.originIndex = a - 1.5f * r.dirIndex;
        r.tNear = 1.5f;
        r.tFar = 1.5f + len;
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
    core::Volume ct = randomVolume<std::int16_t>({9, 6, 5}, 2);
    ct.mapping.slope = 0.5;  // stored → physical, as a CT rescale
    ct.mapping.intercept = -1024.0;
    expectBatchEqualsScalar<std::int16_t>(ct, "int16 rescaled");
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

// The marcher with batches (a uint8 volume) against the marcher without (the same values as
// float32, which samples one at a time): the same image bit for bit and the same sample count in
// emission-absorption, pre-integrated and midpoint, fine and coarse steps, with and without
// skipping and early termination; in gradient mode the same image up to the gradient's rounding
// (the float copy has no difference table).
TEST(SampleBatch, MarcherGivesTheOneAtATimeImage) {
    const core::Volume v = test::smallTorso(48);
    // The torso in HU as uint8 (identity mapping, so the float copy holds the same numbers).
    core::Volume u8(v.geometry(), core::VoxelType::UInt8);
    core::Volume f32(v.geometry(), core::VoxelType::Float32);
    v.visit([&](const auto& view) {
        for (std::uint64_t i = 0; i < v.voxelCount(); ++i) {
            const float hu = view.slope * float(view.data[i]) + view.intercept;
            const auto q = std::uint8_t(std::clamp((hu + 200.f) / 8.f, 0.f, 255.f));
            u8.dataAs<std::uint8_t>()[i] = q;
            f32.dataAs<float>()[i] = float(q);
        }
    });
    const optics::TransferFunction tf(
        {test::tfPoint(20, 0), test::tfPoint(60, 0.2f, {0.9f, 0.4f, 0.3f}),
         test::tfPoint(160, 1.5f)},
        {90, 120});
    const render::Camera cam = test::orthoCamera(v, 30, 20, 0.0, 40);
    int cases = 0;
    for (render::Mode mode : {render::Mode::EmissionAbsorption, render::Mode::Gradient})
        for (bool preint : {true, false})
            for (float step : {0.5f, 2.5f})
                for (bool skipping : {true, false})
                    for (bool termination : {true, false}) {
                        render::RenderOptions o;
                        o.mode = mode;
                        o.preintegrated = preint;
                        o.stepVoxels = step;
                        o.emptySpaceSkipping = skipping;
                        o.earlyTermination = termination;
                        render::RenderStats sb, ss;
                        const core::ImageRGBA a = test::renderWith(u8, tf, cam, o, &sb);
                        const core::ImageRGBA b = test::renderWith(f32, tf, cam, o, &ss);
                        ASSERT_EQ(a.pixels.size(), b.pixels.size());
                        const std::string what =
                            std::string(render::toString(mode)) +
                            (preint ? " preint" : " midpoint") + " step " + std::to_string(step) +
                            (skipping ? " skipping" : "") + (termination ? " termination" : "");
                        if (mode == render::Mode::EmissionAbsorption) {
                            EXPECT_EQ(0, std::memcmp(a.pixels.data(), b.pixels.data(),
                                                     a.pixels.size() * sizeof(float)))
                                << what;
                            EXPECT_EQ(sb.samples, ss.samples) << what;
                        } else {
                            double maxDiff = 0.0;
                            for (std::size_t i = 0; i < a.pixels.size(); ++i)
                                maxDiff =
                                    std::max(maxDiff, double(std::abs(a.pixels[i] - b.pixels[i])));
                            EXPECT_LT(maxDiff, 2e-4) << what;  // as GradientTables' tolerance
                        }
                        ++cases;
                    }
    EXPECT_EQ(cases, 32);
}

#else
TEST(SampleBatch, EightAtATimeEqualsOneAtATime) {
    GTEST_SKIP() << "built without AVX2/FMA: the marcher samples one at a time";
}
#endif

}  // namespace
}  // namespace voxlight
