// SPDX-License-Identifier: MIT
#include "pvrt/radiance.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "core/error.h"
#include "render/dvr_march.h"
#include "render/footprint.h"
#include "sh/sh_basis.h"

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
/// Σ_j w_j t_j blended over the 8 trilinear corners, L = n·3 floats per corner: first the corners'
/// coefficients (8 × L multiply-adds, vectorised with L constant), then one weighted sum per
/// channel (w3[j·3 + ch] = w_j). The sum is linear, so this equals blending the corners' sums up
/// to float rounding.
template <int L>
glm::vec3 blendWeighted(const float* const* corner, const float* cw, const float* w) {
    float w3[L];
    for (int e = 0; e < L; ++e) w3[e] = w[e / 3];
    float acc[L];
    for (int e = 0; e < L; ++e) acc[e] = cw[0] * corner[0][e];
    for (int c = 1; c < 8; ++c)
        for (int e = 0; e < L; ++e) acc[e] += cw[c] * corner[c][e];
    for (int e = 0; e < L; ++e) acc[e] *= w3[e];
    glm::vec3 s(0.f);
    for (int e = 0; e < L; e += 3) s += glm::vec3(acc[e], acc[e + 1], acc[e + 2]);
    return s;
}
}  // namespace

glm::vec3 RadianceVolume::sampleWeighted(const glm::vec3& p, const float* w) const {
    const glm::vec3 g = glm::clamp((p + 0.5f) / scale - 0.5f, glm::vec3(0.f), glm::vec3(res - 1));
    const glm::ivec3 i0 = glm::min(glm::ivec3(g), res - 1);
    const glm::ivec3 i1 = glm::min(i0 + 1, res - 1);
    const glm::vec3 f = g - glm::vec3(i0);
    const std::size_t sy = std::size_t(res.x), sz = std::size_t(res.x) * std::size_t(res.y);
    const std::size_t n = std::size_t(exitance);
    const float* base = &values.data()->x;
    auto at = [&](int x, int y, int z) {
        return base + (std::size_t(x) + sy * std::size_t(y) + sz * std::size_t(z)) * n * 3;
    };
    const float* corner[8] = {at(i0.x, i0.y, i0.z), at(i1.x, i0.y, i0.z), at(i0.x, i1.y, i0.z),
                              at(i1.x, i1.y, i0.z), at(i0.x, i0.y, i1.z), at(i1.x, i0.y, i1.z),
                              at(i0.x, i1.y, i1.z), at(i1.x, i1.y, i1.z)};
    const float gx = 1.f - f.x, gy = 1.f - f.y, gz = 1.f - f.z;
    const float cw[8] = {gx * gy * gz,  f.x * gy * gz,  gx * f.y * gz,  f.x * f.y * gz,
                         gx * gy * f.z, f.x * gy * f.z, gx * f.y * f.z, f.x * f.y * f.z};
    switch (exitance) {
        case 1:
            return blendWeighted<3>(corner, cw, w);
        case 4:
            return blendWeighted<12>(corner, cw, w);
        case 9:
            return blendWeighted<27>(corner, cw, w);
        default:
            return blendWeighted<48>(corner, cw, w);
    }
}

namespace {
/// S clamped at 0 in every channel (NaN → 0 too: max(NaN, 0) would keep it); true when it was
/// negative or NaN somewhere (the count the stats report).
bool clampAtZero(glm::vec3& v) {
    const bool clamped = !(v.x >= 0.f && v.y >= 0.f && v.z >= 0.f);
    for (int c = 0; c < 3; ++c) v[c] = v[c] > 0.f ? v[c] : 0.f;
    return clamped;
}

RadianceVolume emptyLike(const TransferLayout& layout, int exitance) {
    RadianceVolume r;
    r.res = layout.res;
    r.scale = layout.scale;
    r.exitance = exitance;
    r.values.resize(layout.slot.size() * std::size_t(exitance));  // zeros (ZeroedAllocator)
    return r;
}
bool negative(const glm::vec3& v) { return !(v.x >= 0.f && v.y >= 0.f && v.z >= 0.f); }

/// exitanceWeights (transfer.h) in float through the fixed-band SH polynomials (sh::evalSh) — per
/// grid point of EyeFold, where the double recurrence cost more than the combination; equal to it
/// within float rounding (tests).
template <int n>
void eyeWeights(float g, const glm::vec3& toEye, float* w) {
    constexpr int band = n == 4 ? 1 : n == 9 ? 2 : 3;
    float y[n];
    sh::evalSh(band, -toEye, std::span<float>(y, n));
    const float s = std::sqrt(4.f * std::numbers::pi_v<float>);
    w[0] = 1.f;
    float gl = 1.f;
    for (int l = 1, j = 1; j < n; ++l) {
        gl *= g;
        for (int m = -l; m <= l; ++m, ++j) w[j] = gl * s * y[j];
    }
}

/// EyeFold's ω_eye at the grid points: −forward (orthographic), or the unit world direction from
/// the point to the eye (perspective).
class EyeDirections {
  public:
    EyeDirections(const TransferLayout& layout, const EyeFold* eye) : layout_(layout), eye_(eye) {
        if (!eye) return;
        ortho_ = glm::vec3(-glm::normalize(eye->forward));
        // Perspective: eye − x in voxel coordinates, then to world directions (index → world is
        // direction · diag(spacing); rows of its transpose applied as v · M).
        eyeIndex_ = glm::vec3(eye->geometry.worldToIndex(eye->eye));
        indexToWorld_ = glm::mat3(glm::transpose(
            eye->geometry.direction * glm::dmat3(glm::dvec3(eye->geometry.spacing.x, 0, 0),
                                                 glm::dvec3(0, eye->geometry.spacing.y, 0),
                                                 glm::dvec3(0, 0, eye->geometry.spacing.z))));
    }
    /// At grid point i (x fastest) of slice z.
    glm::vec3 at(std::size_t i, int z) const {
        if (eye_->orthographic) return ortho_;
        const std::size_t perSlice = std::size_t(layout_.res.x) * std::size_t(layout_.res.y);
        const std::size_t xy = i - perSlice * std::size_t(z);
        const glm::ivec3 g(int(xy % std::size_t(layout_.res.x)),
                           int(xy / std::size_t(layout_.res.x)), z);
        return glm::normalize((eyeIndex_ - layout_.position(g)) * indexToWorld_);
    }

  private:
    const TransferLayout& layout_;
    const EyeFold* eye_;
    glm::vec3 ortho_{0.f}, eyeIndex_{0.f};
    glm::mat3 indexToWorld_{1.f};
};

/// Σ_j w_j t_j per channel, with w = eyeWeights<n> toward ω_eye.
glm::vec3 evaluateTowardEye(int n, float g, const glm::vec3& toEye, const glm::vec3* t) {
    float w[16];
    switch (n) {
        case 4:
            eyeWeights<4>(g, toEye, w);
            break;
        case 9:
            eyeWeights<9>(g, toEye, w);
            break;
        default:
            eyeWeights<16>(g, toEye, w);
            break;
    }
    glm::vec3 sum(0.f);
    for (int j = 0; j < n; ++j) sum += w[j] * t[j];
    return sum;
}
}  // namespace

RadianceVolume combineTransfer(const Transfer& transfer, std::span<const glm::vec3> light,
                               int threads, const EyeFold* eye) {
    VL_CHECK_EQ(int(light.size()), transfer.basis);
    const TransferLayout& layout = transfer.layout;
    const int m = transfer.basis;
    const int n = transfer.exitance;
    if (n == 1) eye = nullptr;  // isotropic: nothing to evaluate toward the eye
    RadianceVolume r = emptyLike(layout, eye ? 1 : n);
    r.towardEye = eye != nullptr;
    const EyeDirections toward(layout, eye);
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
                if (n > 1) {
                    glm::vec3 coeff[16];
                    for (int j = 0; j < n; ++j) {
                        glm::vec3 sum(0.f);
                        for (int k = 0; k < m; ++k, t += 3)
                            sum += glm::vec3(t[0], t[1], t[2]) * light[std::size_t(k)];
                        coeff[j] = sum;
                    }
                    if (eye) {
                        const glm::vec3 ls = evaluateTowardEye(n, eye->g, toward.at(i, z), coeff);
                        clamped += negative(ls) ? 1 : 0;
                        r.values[i] = ls;
                        continue;
                    }
                    clamped += negative(coeff[0]) ? 1 : 0;
                    for (int j = 0; j < n; ++j)
                        r.values[i * std::size_t(n) + std::size_t(j)] = coeff[j];
                    continue;
                }
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

namespace {
/// scatterRadiance for n > 1 coefficients (not clamped): 16× the data of n = 1, so parallel over
/// z-slices of the grid (each writes its own slots; the count is summed per slice in order).
RadianceVolume scatterCoefficients(const TransferLayout& layout,
                                   std::span<const glm::vec3> perPoint, int exitance) {
    RadianceVolume r;
    r.res = layout.res;
    r.scale = layout.scale;
    r.exitance = exitance;
    r.values.resize(layout.slot.size() * std::size_t(exitance));
    const std::size_t n = std::size_t(exitance);
    const std::size_t perSlice = std::size_t(layout.res.x) * std::size_t(layout.res.y);
    std::vector<std::uint64_t> clampedPerSlice(std::size_t(std::max(layout.res.z, 0)), 0);
    tbb::parallel_for(tbb::blocked_range<int>(0, layout.res.z),
                      [&](const tbb::blocked_range<int>& zs) {
                          for (int z = zs.begin(); z < zs.end(); ++z) {
                              std::uint64_t clamped = 0;
                              for (std::size_t i = perSlice * std::size_t(z);
                                   i < perSlice * std::size_t(z + 1); ++i) {
                                  const std::int32_t s = layout.slot[i];
                                  glm::vec3* dst = r.values.data() + i * n;
                                  if (s < 0) {
                                      std::fill(dst, dst + n, glm::vec3(0.f));
                                      continue;
                                  }
                                  std::copy_n(perPoint.data() + std::size_t(s) * n, n, dst);
                                  clamped += negative(dst[0]) ? 1 : 0;
                              }
                              clampedPerSlice[std::size_t(z)] = clamped;
                          }
                      });
    for (std::uint64_t c : clampedPerSlice) r.clamped += c;
    return r;
}
}  // namespace

RadianceVolume scatterRadiance(const TransferLayout& layout, std::span<const glm::vec3> perPoint,
                               int exitance) {
    VL_CHECK(validExitance(exitance));
    VL_CHECK_EQ(perPoint.size(), std::size_t(layout.points) * std::size_t(exitance));
    if (exitance > 1) return scatterCoefficients(layout, perPoint, exitance);
    RadianceVolume r = emptyLike(layout, exitance);
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
/// One stored point of combineCpca: out[e] = p[e] + Σ_i w_i·p[(1+i)·L + e], e < L = n·3, summed
/// in the order of Cpca::radiance (mean first, then the components in order). L is a constant
/// so the loops vectorise.
template <int L>
void combinePoint(const float* p, const float* w, int components, float* out) {
    float acc[L];
    for (int e = 0; e < L; ++e) acc[e] = p[e];
    for (int i = 0; i < components; ++i) {
        const float wi = w[i];
        const float* b = p + std::size_t(1 + i) * L;
        for (int e = 0; e < L; ++e) acc[e] += wi * b[e];
    }
    for (int e = 0; e < L; ++e) out[e] = acc[e];
}

template <int L>
void combineSlices(const TransferLayout& layout, const Cpca& cpca, const float* projected,
                   const EyeFold* eye, RadianceVolume& r,
                   std::vector<std::uint64_t>& clampedPerSlice, const tbb::blocked_range<int>& zs) {
    constexpr int n = L / 3;
    const int N = cpca.components;
    const std::size_t perCluster = std::size_t(N + 1) * L;
    const std::size_t perSlice = std::size_t(layout.res.x) * std::size_t(layout.res.y);
    const std::size_t stride = eye ? 3 : L;  // floats per grid point written
    float* values = &r.values.data()->x;
    const EyeDirections toward(layout, eye);
    for (int z = zs.begin(); z < zs.end(); ++z) {
        std::uint64_t clamped = 0;
        for (std::size_t i = perSlice * std::size_t(z); i < perSlice * std::size_t(z + 1); ++i) {
            const std::int32_t s = layout.slot[i];
            if (s < 0) continue;  // stays 0 (fresh zeroed pages)
            float* out = values + i * stride;
            float t[L];
            combinePoint<L>(projected + std::size_t(cpca.cluster[std::size_t(s)]) * perCluster,
                            cpca.weights.data() + std::size_t(s) * std::size_t(N), N,
                            eye ? t : out);
            if (eye) {
                float w[n];
                if constexpr (n > 1) eyeWeights<n>(eye->g, toward.at(i, z), w);
                // Σ_j w_j t_j per channel: the weights spread over the n·3 entries, one vector
                // product, then the three channels' sums.
                float w3[L];
                for (int e = 0; e < L; ++e) w3[e] = w[e / 3];
                for (int e = 0; e < L; ++e) t[e] *= w3[e];
                glm::vec3 sum(0.f);
                for (int e = 0; e < L; e += 3) sum += glm::vec3(t[e], t[e + 1], t[e + 2]);
                out[0] = sum.x, out[1] = sum.y, out[2] = sum.z;
                clamped += negative(sum) ? 1 : 0;
                continue;
            }
            glm::vec3 v(out[0], out[1], out[2]);
            if constexpr (n == 1) {
                clamped += clampAtZero(v) ? 1 : 0;
                out[0] = v.x, out[1] = v.y, out[2] = v.z;
            } else {
                clamped += negative(v) ? 1 : 0;
            }
        }
        clampedPerSlice[std::size_t(z)] = clamped;
    }
}
}  // namespace

RadianceVolume combineCpca(const TransferLayout& layout, const Cpca& cpca,
                           std::span<const glm::vec3> light, int exitance, int threads,
                           const EyeFold* eye) {
    VL_CHECK(validExitance(exitance));
    VL_CHECK_EQ(cpca.rows(), std::size_t(layout.points));
    static_assert(sizeof(glm::vec3) == 3 * sizeof(float));
    if (exitance == 1) eye = nullptr;  // isotropic: nothing to evaluate toward the eye
    RadianceVolume r = emptyLike(layout, eye ? 1 : exitance);
    r.towardEye = eye != nullptr;
    std::vector<std::uint64_t> clampedPerSlice(std::size_t(std::max(layout.res.z, 0)), 0);
    tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
    arena.execute([&] {
        const std::vector<float> projected = cpca.projectLight(light, exitance);
        const float* p = projected.data();
        const tbb::blocked_range<int> all(0, layout.res.z);
        auto run = [&](auto body) { tbb::parallel_for(all, body); };
        switch (exitance) {
            case 1:
                run([&](const auto& zs) {
                    combineSlices<3>(layout, cpca, p, eye, r, clampedPerSlice, zs);
                });
                break;
            case 4:
                run([&](const auto& zs) {
                    combineSlices<12>(layout, cpca, p, eye, r, clampedPerSlice, zs);
                });
                break;
            case 9:
                run([&](const auto& zs) {
                    combineSlices<27>(layout, cpca, p, eye, r, clampedPerSlice, zs);
                });
                break;
            default:
                run([&](const auto& zs) {
                    combineSlices<48>(layout, cpca, p, eye, r, clampedPerSlice, zs);
                });
                break;
        }
    });
    for (std::uint64_t c : clampedPerSlice) r.clamped += c;
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
        glm::vec3 s = radiance_->sample(worldToIndex_ * (in.position - origin_));
        // L_s evaluated toward the eye per grid point (EyeFold) is clamped after the blend, as
        // the per-sample evaluation; S (n = 1) is ≥ 0 already, so this changes nothing there.
        clampAtZero(s);
        return {s, glm::vec3(0.f)};
    }
    const PvrtShader& forRay(const glm::vec3&) const { return *this; }

  private:
    std::shared_ptr<const RadianceVolume> radiance_;
    glm::mat3 worldToIndex_{1.f};
    glm::vec3 origin_{0.f};
};

/// n > 1 exitance coefficients: Henyey–Greenstein in-scattered radiance toward the eye. The
/// per-ray copy holds the weights g^l·Ŷ_j(−toEye) (toEye is the same along a ray); with a TF
/// phase g channel only Ŷ_j, and g^l per sample from the TF at the sample's value.
class PvrtHgShader {
  public:
    static constexpr bool kNeedsNormal = false;
    static constexpr bool kScatterAtMeanDepth = true;
    PvrtHgShader(std::shared_ptr<const RadianceVolume> radiance, const core::Geometry& geometry,
                 float g, std::shared_ptr<const optics::TfTable> table)
        : radiance_(std::move(radiance)),
          table_(table && table->hasPhaseG() ? std::move(table) : nullptr),
          worldToIndex_(geometry.worldToIndexMatrix()),
          origin_(geometry.origin),
          g_(g) {}
    render::Scatter scatter(const render::ShadeInput& in) const {
        const glm::vec3 p = worldToIndex_ * (in.position - origin_);
        glm::vec3 s;
        if (table_) {
            const float g = table_->surface(in.value).phaseG;
            float w[kMaxExitance];
            float gl = 1.f;
            for (int l = 0, j = 0; j < radiance_->exitance; ++l, gl *= g)
                for (int m = -l; m <= l; ++m, ++j) w[j] = gl * w_[std::size_t(j)];
            s = radiance_->sampleWeighted(p, w);
        } else {
            s = radiance_->sampleWeighted(p, w_.data());
        }
        clampAtZero(s);  // radiance is never negative (NaN → 0 too)
        return {s, glm::vec3(0.f)};
    }
    PvrtHgShader forRay(const glm::vec3& toEye) const {
        PvrtHgShader r = *this;
        // With a phase channel: Ŷ_j(−toEye) alone (g = 1), the g^l come per sample.
        exitanceWeights(radiance_->exitance, table_ ? 1.f : g_, toEye, r.w_.data());
        return r;
    }

  private:
    std::shared_ptr<const RadianceVolume> radiance_;
    std::shared_ptr<const optics::TfTable> table_;
    glm::mat3 worldToIndex_{1.f};
    glm::vec3 origin_{0.f};
    float g_ = 0.f;
    std::array<float, kMaxExitance> w_{};
};

}  // namespace

std::unique_ptr<render::ShadingModel> makePvrtModel(const render::RayCaster& caster,
                                                    const render::Camera& camera,
                                                    std::shared_ptr<const RadianceVolume> radiance,
                                                    float phaseG,
                                                    std::shared_ptr<const optics::TfTable> table) {
    if (radiance->exitance > 1)
        return std::make_unique<render::detail::DvrModel<PvrtHgShader>>(
            "pvrt", PvrtHgShader(std::move(radiance), caster.volume().geometry(), phaseG, table),
            render::PixelFootprint(caster, camera));
    return std::make_unique<render::detail::DvrModel<PvrtShader>>(
        "pvrt", PvrtShader(std::move(radiance), caster.volume().geometry()),
        render::PixelFootprint(caster, camera));
}

}  // namespace voxlight::pvrt
