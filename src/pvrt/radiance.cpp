// SPDX-License-Identifier: MIT
#include "pvrt/radiance.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "render/dvr_march.h"
#include "render/footprint.h"

namespace voxlight::pvrt {

glm::vec3 RadianceVolume::sample(const glm::vec3& p) const {
    const glm::vec3 g = glm::clamp((p + 0.5f) / scale - 0.5f, glm::vec3(0.f), glm::vec3(res - 1));
    const glm::ivec3 i0 = glm::min(glm::ivec3(g), res - 1);
    const glm::ivec3 i1 = glm::min(i0 + 1, res - 1);
    const glm::vec3 f = g - glm::vec3(i0);
    const std::size_t sy = std::size_t(res.x), sz = std::size_t(res.x) * std::size_t(res.y);
    auto at = [&](int x, int y, int z) {
        return values[std::size_t(x) + sy * std::size_t(y) + sz * std::size_t(z)];
    };
    const glm::vec3 c00 = glm::mix(at(i0.x, i0.y, i0.z), at(i1.x, i0.y, i0.z), f.x);
    const glm::vec3 c10 = glm::mix(at(i0.x, i1.y, i0.z), at(i1.x, i1.y, i0.z), f.x);
    const glm::vec3 c01 = glm::mix(at(i0.x, i0.y, i1.z), at(i1.x, i0.y, i1.z), f.x);
    const glm::vec3 c11 = glm::mix(at(i0.x, i1.y, i1.z), at(i1.x, i1.y, i1.z), f.x);
    return glm::mix(glm::mix(c00, c10, f.y), glm::mix(c01, c11, f.y), f.z);
}

namespace {
/// S clamped at 0 in every channel (NaN → 0 too: max(NaN, 0) would keep it); true when it was
/// negative or NaN somewhere (the count the stats report).
bool clampAtZero(glm::vec3& v) {
    const bool clamped = !(v.x >= 0.f && v.y >= 0.f && v.z >= 0.f);
    for (int c = 0; c < 3; ++c) v[c] = v[c] > 0.f ? v[c] : 0.f;
    return clamped;
}

RadianceVolume emptyLike(const TransferLayout& layout) {
    RadianceVolume r;
    r.res = layout.res;
    r.scale = layout.scale;
    r.values.assign(layout.slot.size(), glm::vec3(0.f));
    return r;
}
}  // namespace

RadianceVolume combineTransfer(const Transfer& transfer, std::span<const glm::vec3> light,
                               int threads) {
    VL_CHECK_EQ(int(light.size()), transfer.basis);
    const TransferLayout& layout = transfer.layout;
    RadianceVolume r = emptyLike(layout);
    const int m = transfer.basis;
    const std::size_t perSlice = std::size_t(layout.res.x) * std::size_t(layout.res.y);
    std::vector<std::uint64_t> clampedPerSlice(std::size_t(std::max(layout.res.z, 0)), 0);
    auto body = [&](const tbb::blocked_range<int>& zs) {
        for (int z = zs.begin(); z < zs.end(); ++z) {
            std::uint64_t clamped = 0;
            for (std::size_t i = perSlice * std::size_t(z); i < perSlice * std::size_t(z + 1);
                 ++i) {
                const std::int32_t s = layout.slot[i];
                if (s < 0) continue;
                const float* t = transfer.row(s);
                glm::vec3 sum(0.f);
                for (int k = 0; k < m; ++k, t += 3)
                    sum += glm::vec3(t[0], t[1], t[2]) * light[std::size_t(k)];
                clamped += clampAtZero(sum) ? 1 : 0;
                r.values[i] = sum;
            }
            clampedPerSlice[std::size_t(z)] = clamped;
        }
    };
    tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
    arena.execute([&] { tbb::parallel_for(tbb::blocked_range<int>(0, layout.res.z), body); });
    for (std::uint64_t c : clampedPerSlice) r.clamped += c;
    return r;
}

RadianceVolume scatterRadiance(const TransferLayout& layout, std::span<const glm::vec3> perPoint) {
    VL_CHECK_EQ(perPoint.size(), std::size_t(layout.points));
    RadianceVolume r = emptyLike(layout);
    for (std::size_t i = 0; i < layout.slot.size(); ++i) {
        const std::int32_t s = layout.slot[i];
        if (s < 0) continue;
        glm::vec3 v = perPoint[std::size_t(s)];
        r.clamped += clampAtZero(v) ? 1 : 0;
        r.values[i] = v;
    }
    return r;
}

namespace {

/// In-scattered radiance from the radiance volume at the sample (isotropic: no view dependence).
class PvrtShader {
  public:
    static constexpr bool kNeedsNormal = false;
    /// Segments are shaded where their light is scattered (render/dvr_march.h meanScatterDepth).
    static constexpr bool kScatterAtMeanDepth = true;
    PvrtShader(std::shared_ptr<const RadianceVolume> radiance, const core::Geometry& geometry)
        : radiance_(std::move(radiance)),
          worldToIndex_(geometry.worldToIndexMatrix()),
          origin_(geometry.origin) {}
    render::Scatter scatter(const render::ShadeInput& in) const {
        return {radiance_->sample(worldToIndex_ * (in.position - origin_)), glm::vec3(0.f)};
    }
    const PvrtShader& forRay(const glm::vec3&) const { return *this; }

  private:
    std::shared_ptr<const RadianceVolume> radiance_;
    glm::mat3 worldToIndex_{1.f};
    glm::vec3 origin_{0.f};
};

}  // namespace

std::unique_ptr<render::ShadingModel> makePvrtModel(
    const render::RayCaster& caster, const render::Camera& camera,
    std::shared_ptr<const RadianceVolume> radiance) {
    return std::make_unique<render::detail::DvrModel<PvrtShader>>(
        "pvrt", PvrtShader(std::move(radiance), caster.volume().geometry()),
        render::PixelFootprint(caster, camera));
}

}  // namespace voxlight::pvrt
