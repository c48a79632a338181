// SPDX-License-Identifier: MIT
#include "visibility/global_visibility.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <cmath>
#include <numbers>
#include <thread>

#include "core/error.h"
#include "sh/sh_basis.h"

namespace voxlight::visibility {

namespace {
const float kInvSqrt4Pi = float(1.0 / std::sqrt(4.0 * std::numbers::pi));
}  // namespace

GlobalVisibility computeGlobalVisibility(std::shared_ptr<const LocalVisibility> localPtr,
                                         const GlobalVisibilityOptions& options,
                                         const core::Progress& progress) {
    VL_CHECK(localPtr != nullptr);
    if (options.resolution < 1)
        throw InputError("global visibility", "resolution",
                         "must be at least 1, got " + std::to_string(options.resolution),
                         "give e.g. 64");
    const LocalVisibility& local = *localPtr;
    const MultiresGrid& grid = local.grid();
    const int C = local.coefficients();
    const sh::SphereSamples& dirs = local.directions();
    const int N = int(dirs.size());
    const core::Geometry& geo = grid.pyramid().geometry();
    const glm::ivec3 dims = grid.dims();

    GlobalVisibility out;
    out.local_ = localPtr;
    if (options.nearFromLocal) out.product_ = std::make_shared<const sh::ShProduct>(C);
    const int firstPiece = options.nearFromLocal ? 1 : 0;
    out.coefficients_ = C;
    out.res_ = glm::min(glm::ivec3(options.resolution), dims);
    out.scale_ = glm::vec3(dims) / glm::vec3(out.res_);
    out.data_.assign(std::size_t(out.res_.x) * out.res_.y * out.res_.z * C, 0.f);
    if (options.nearFromLocal)  // openness weights only the split's far interpolation
        out.open_.assign(std::size_t(out.res_.x) * out.res_.y * out.res_.z, 1.f);
    const float spacing = std::max({out.scale_.x, out.scale_.y, out.scale_.z});

    // Per direction: the step of r_s in index space, and Y_i(ω_k) (unweighted, for eq. 11) and
    // w_k·Y_i(ω_k) (for the projection).
    const double h = core::minComponent(geo.spacing);
    std::vector<glm::vec3> step(static_cast<std::size_t>(N));
    std::vector<float> y(static_cast<std::size_t>(N) * C);
    std::vector<double> wy(static_cast<std::size_t>(N) * C);
    std::vector<double> yd(static_cast<std::size_t>(sh::kMaxCoeffs));
    for (int k = 0; k < N; ++k) {
        const glm::dvec3& w = dirs.directions[std::size_t(k)];
        step[std::size_t(k)] = glm::vec3((glm::transpose(geo.direction) * w) / geo.spacing *
                                         (local.radiusVoxels() * h));
        sh::evalShUnitDouble(sh::shBandForCount(C), w, yd);
        for (int i = 0; i < C; ++i) {
            y[std::size_t(k) * C + i] = float(yd[std::size_t(i)]);
            wy[std::size_t(k) * C + i] = dirs.weights[std::size_t(k)] * yd[std::size_t(i)];
        }
    }
    const glm::vec3 hi(dims - 1);
    auto inside = [&](const glm::vec3& p) {
        return p.x >= 0.f && p.y >= 0.f && p.z >= 0.f && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
    };

    std::atomic<std::uint64_t> raysTotal{0}, skippedTotal{0};
    std::atomic<int> done{0};
    const std::thread::id caller = std::this_thread::get_id();
    progress.report("global visibility", 0.0);
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
    arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<int>(0, out.res_.z), [&](const auto& range) {
            if (progress.cancelled()) return;
            std::uint64_t rays = 0, skipped = 0;
            float vl[16];
            double v[16];
            for (int gz = range.begin(); gz != range.end(); ++gz)
                for (int gy = 0; gy < out.res_.y; ++gy)
                    for (int gx = 0; gx < out.res_.x; ++gx) {
                        const glm::ivec3 g(gx, gy, gz);
                        float* dst = const_cast<float*>(out.at(g));
                        const glm::vec3 x = glm::min(out.position(g), hi);
                        if (!visibilityNeeded(grid, x, spacing)) {
                            dst[0] = float(std::sqrt(4.0 * std::numbers::pi));
                            ++skipped;
                            continue;
                        }
                        if (options.nearFromLocal) {
                            local.sample(x, vl);
                            out.open_[out.index(g)] = std::clamp(vl[0] * kInvSqrt4Pi, 0.f, 1.f);
                        }
                        std::fill(v, v + C, 0.0);
                        for (int k = 0; k < N; ++k) {
                            // Piecewise integration in steps of r_s (eq. 11), front to back,
                            // from the second piece on when the first is the local field's.
                            const float* yk = y.data() + std::size_t(k) * C;
                            double T = 1.0;
                            for (glm::vec3 p = x + float(firstPiece) * step[std::size_t(k)];
                                 inside(p) && T >= kGlobalStopT; p += step[std::size_t(k)]) {
                                local.sample(p, vl);
                                float t = 0.f;
                                for (int i = 0; i < C; ++i) t += vl[i] * yk[i];
                                T *= std::min(std::max(double(t), 0.0), 1.0);
                            }
                            const double* w = wy.data() + std::size_t(k) * C;
                            for (int i = 0; i < C; ++i) v[i] += T * w[i];
                        }
                        rays += std::uint64_t(N);
                        for (int i = 0; i < C; ++i) dst[i] = float(v[i]);
                    }
            raysTotal += rays;
            skippedTotal += skipped;
            const int now = done.fetch_add(int(range.size())) + int(range.size());
            if (std::this_thread::get_id() == caller)
                progress.report("global visibility", double(now) / out.res_.z);
        });
    });
    if (progress.cancelled()) throw CancelledError();
    progress.report("global visibility", 1.0);
    out.rays_ = raysTotal;
    out.skipped_ = skippedTotal;
    return out;
}

void GlobalVisibility::sample(const glm::vec3& p, float* out) const {
    if (!product_) return sampleFar(p, out);
    float nearV[16], farV[16];
    local_->sample(p, nearV);
    sampleFar(p, farV);
    product_->apply(nearV, farV, out);
}

void GlobalVisibility::sampleFar(const glm::vec3& p, float* out) const {
    const int C = coefficients_;
    float total = 0.f;
    glm::vec3 u = (p + 0.5f) / scale_ - 0.5f;
    u = glm::clamp(u, glm::vec3(0.f), glm::vec3(res_ - 1));
    const glm::ivec3 i0 = glm::min(glm::ivec3(u), glm::max(res_ - 2, glm::ivec3(0)));
    const glm::vec3 f = u - glm::vec3(i0);
    std::fill(out, out + C, 0.f);
    for (int c = 0; c < 8; ++c) {
        const glm::ivec3 o((c & 1), (c >> 1) & 1, c >> 2);
        const glm::ivec3 g = glm::min(i0 + o, res_ - 1);
        const float w = (o.x ? f.x : 1.f - f.x) * (o.y ? f.y : 1.f - f.y) *
                        (o.z ? f.z : 1.f - f.z) *
                        (product_ ? open_[index(g)] + kBuriedWeight : 1.f);
        if (w == 0.f) continue;
        total += w;
        const float* d = at(g);
        for (int i = 0; i < C; ++i) out[i] += w * d[i];
    }
    if (!product_) return;  // plain trilinear: the weights sum to 1
    const float inv = 1.f / total;
    for (int i = 0; i < C; ++i) out[i] *= inv;
}

}  // namespace voxlight::visibility
