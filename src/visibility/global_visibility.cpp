// SPDX-License-Identifier: MIT
#include "visibility/global_visibility.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numbers>
#include <thread>

#include "core/error.h"
#include "sh/sh_basis.h"

namespace voxlight::visibility {

namespace {
const float kInvSqrt4Pi = float(1.0 / std::sqrt(4.0 * std::numbers::pi));
/// Grid steps beyond 1 that a piece must move along its dominant axis for the recursive
/// integration: its far end's trilinear stencil then lies wholly in planes already computed.
constexpr float kRecursiveMargin = 1e-3f;
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
    // Per point [openness, V^F_0 … V^F_{C−1}] while computed (openness 1 where skipped, and
    // everywhere without the split: it weights only the split's far interpolation); pack() turns
    // it into the weighted form in place.
    const std::size_t S = std::size_t(C) + 1;
    out.packed_.assign(std::size_t(out.res_.x) * out.res_.y * out.res_.z * S, 0.f);
    for (std::size_t i = 0; i < out.packed_.size(); i += S) out.packed_[i] = 1.f;
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
    // Eq. 11 from p along direction k: pieces of r_s read from the local field, front to back,
    // until the box or kGlobalStopT (vl: C floats of scratch).
    auto chain = [&](glm::vec3 p, int k, float* vl) {
        const float* yk = y.data() + std::size_t(k) * C;
        double T = 1.0;
        for (; inside(p) && T >= kGlobalStopT; p += step[std::size_t(k)]) {
            local.sample(p, vl);
            float t = 0.f;
            for (int i = 0; i < C; ++i) t += vl[i] * yk[i];
            T *= std::min(std::max(double(t), 0.0), 1.0);
        }
        return T;
    };

    std::atomic<std::uint64_t> raysTotal{0}, skippedTotal{0};
    std::atomic<int> done{0};
    const std::thread::id caller = std::this_thread::get_id();
    progress.report("global visibility", 0.0);
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);

    // Recursive integration: usable when every direction moves at least one grid step (plus a
    // margin against rounding) along its dominant axis per piece.
    std::vector<int> dominant(static_cast<std::size_t>(N));
    bool recursive = options.integration == GlobalIntegration::Recursive;
    for (int k = 0; k < N; ++k) {
        const glm::vec3 sg = step[std::size_t(k)] / out.scale_;
        int a = 0;
        for (int b = 1; b < 3; ++b)
            if (std::abs(sg[b]) > std::abs(sg[a])) a = b;
        dominant[std::size_t(k)] = a;
        if (!(std::abs(sg[a]) >= 1.f + kRecursiveMargin)) recursive = false;
    }
    if (options.integration == GlobalIntegration::Recursive && !recursive)
        out.integrationNote_ = "piecewise: r_s is under one grid step along some direction";
    const std::size_t transient = recursiveTransientBytes(out.res_, C, options.nearFromLocal);
    if (recursive && transient > options.maxRecursiveBytes) {
        recursive = false;
        out.integrationNote_ = "piecewise: the recursive integration would hold " +
                               std::to_string(transient >> 20) + " MiB besides the field, over " +
                               std::to_string(options.maxRecursiveBytes >> 20) + " MiB";
    }
    if (recursive) {
        out.integration_ = GlobalIntegration::Recursive;
        const std::size_t P = std::size_t(out.res_.x) * out.res_.y * out.res_.z;
        // The local field once per grid point; which points are shaded (the rest: empty space).
        // Uninitialised (every element is written below before it is read): zero-filling these
        // and the groups' grids was a serial memset of ~25 MB on the calling thread.
        const auto vl = std::make_unique_for_overwrite<float[]>(P * std::size_t(C));
        const auto needed = std::make_unique_for_overwrite<std::uint8_t[]>(P);
        arena.execute([&] {
            tbb::parallel_for(tbb::blocked_range<int>(0, out.res_.z), [&](const auto& range) {
                for (int gz = range.begin(); gz != range.end(); ++gz)
                    for (int gy = 0; gy < out.res_.y; ++gy)
                        for (int gx = 0; gx < out.res_.x; ++gx) {
                            const glm::ivec3 g(gx, gy, gz);
                            const std::size_t i = out.index(g);
                            const glm::vec3 x = glm::min(out.position(g), hi);
                            local.sample(x, vl.get() + i * std::size_t(C));
                            needed[i] = visibilityNeeded(grid, x, spacing) ? 1 : 0;
                        }
            });
        });
        const glm::ivec3 res = out.res_;
        // One direction, sequentially: F_k into F, the far part into far.
        auto direction = [&](int k, float* F, float* far) {
            const glm::vec3 sk = step[std::size_t(k)];
            const int a = dominant[std::size_t(k)];
            // The plane's two axes, the one with the smaller stride innermost (x before y before
            // z): points within a plane are independent, and a z-innermost walk strides a whole
            // plane of the grid per point.
            const int b = a == 0 ? 1 : 0, c = a == 2 ? 1 : 2;
            const bool forward = sk[a] > 0.f;  // the far end lies toward larger a
            const float* yk = y.data() + std::size_t(k) * C;
            auto piece = [&](const float* v) {
                float t = 0.f;
                for (int i = 0; i < C; ++i) t += v[i] * yk[i];
                return std::min(std::max(t, 0.f), 1.f);
            };
            // F_k's far end sits at grid coordinate g + d for every point g (the grid is regular),
            // so the trilinear stencil has fixed corners and weights: offsets into F and weights
            // once per direction; points whose stencil or far end crosses the grid's or the box's
            // edge take the clamped general read below.
            const glm::vec3 d = sk / out.scale_;
            const glm::ivec3 fl(glm::floor(d));
            const glm::vec3 f = d - glm::vec3(fl);
            std::ptrdiff_t off[8];
            float w[8];
            for (int q = 0; q < 8; ++q) {
                const glm::ivec3 o = fl + glm::ivec3(q & 1, (q >> 1) & 1, q >> 2);
                off[q] =
                    std::ptrdiff_t(o.x) +
                    std::ptrdiff_t(res.x) * (std::ptrdiff_t(o.y) + std::ptrdiff_t(res.y) * o.z);
                w[q] = ((q & 1) ? f.x : 1.f - f.x) * ((q & 2) ? f.y : 1.f - f.y) *
                       ((q & 4) ? f.z : 1.f - f.z);
            }
            // Per axis, the points whose far end is inside the box and whose stencil is inside
            // the grid.
            glm::ivec3 lo, up;
            for (int e = 0; e < 3; ++e) {
                lo[e] = std::max(0, -fl[e]);
                up[e] = std::min(res[e] - 1, res[e] - 2 - fl[e]);
                while (lo[e] <= up[e] && !(out.position(glm::ivec3(lo[e]))[e] + sk[e] >= 0.f))
                    ++lo[e];
                while (up[e] >= lo[e] && !(out.position(glm::ivec3(up[e]))[e] + sk[e] <= hi[e]))
                    --up[e];
            }
            auto readF = [&](const glm::vec3& u) {  // clamped per axis
                glm::ivec3 i0, i1;
                glm::vec3 fr;
                for (int e = 0; e < 3; ++e) {
                    const float ue = std::min(std::max(u[e], 0.f), float(res[e] - 1));
                    i0[e] = int(ue);
                    i1[e] = std::min(i0[e] + 1, res[e] - 1);
                    fr[e] = ue - float(i0[e]);
                }
                float v = 0.f;
                for (int q = 0; q < 8; ++q) {
                    const float wq = ((q & 1) ? fr.x : 1.f - fr.x) * ((q & 2) ? fr.y : 1.f - fr.y) *
                                     ((q & 4) ? fr.z : 1.f - fr.z);
                    if (wq == 0.f) continue;
                    const glm::ivec3 g((q & 1) ? i1.x : i0.x, (q & 2) ? i1.y : i0.y,
                                       (q & 4) ? i1.z : i0.z);
                    v += wq * F[out.index(g)];
                }
                return v;
            };
            float vq[16];
            // A point whose far end's stencil leaves the grid or whose far end lies outside the
            // box: the clamped read, eq. 11 piece by piece, or nothing past the box.
            auto edgePoint = [&](const glm::ivec3& g, std::size_t i) {
                float t = 1.f;
                const glm::vec3 q = glm::min(out.position(g), hi) + sk;
                if (inside(q)) {
                    const glm::vec3 u = glm::vec3(g) + d;
                    bool inGrid = true;
                    for (int e = 0; e < 3; ++e)
                        inGrid = inGrid && u[e] >= 0.f && u[e] <= float(res[e] - 1);
                    if (inGrid) {
                        t = readF(u);
                    } else {
                        // Inside the box but beyond its outermost grid points on some axis
                        // (within half a grid step of a face): a clamped read would take F of
                        // points up to a step farther from that face, where rays leaving through
                        // it have farther to go. The rest of the chain piece by piece instead, as
                        // eq. 11 (past the last plane along the dominant axis that is one piece,
                        // then the box).
                        t = float(chain(q, k, vq));
                    }
                }
                if (far) far[i] = t;
                F[i] = piece(vl.get() + i * std::size_t(C)) * t;
            };
            const std::size_t strideB = b == 0 ? 1 : std::size_t(res.x);
            for (int n = 0; n < res[a]; ++n) {
                if (progress.cancelled()) return;
                glm::ivec3 g;
                g[a] = forward ? res[a] - 1 - n : n;
                const bool planeFast = g[a] >= lo[a] && g[a] <= up[a];
                for (g[c] = 0; g[c] < res[c]; ++g[c]) {
                    // The row's points whose stencil is fixed (lo..up along b) in one branch-free
                    // run; every tap lies in a plane already computed (the far end is over a grid
                    // step ahead along a), so a zero weight adds an exact 0: the same sums as
                    // tap by tap.
                    const bool rowFast =
                        planeFast && g[c] >= lo[c] && g[c] <= up[c] && lo[b] <= up[b];
                    const int fastLo = rowFast ? lo[b] : res[b];
                    const int fastEnd = rowFast ? up[b] + 1 : res[b];  // first point after the run
                    for (g[b] = 0; g[b] < fastLo; ++g[b]) edgePoint(g, out.index(g));
                    if (rowFast) {
                        const std::size_t i0 = out.index(g);  // g[b] = fastLo
                        const std::size_t count = std::size_t(fastEnd - fastLo);
                        float* const Fr = F + i0;
                        float* const farRow = far ? far + i0 : nullptr;
                        const float* const vr = vl.get() + i0 * std::size_t(C);
                        for (std::size_t u = 0; u < count; ++u) {
                            const float* Fi = Fr + u * strideB;
                            float t = 0.f;
                            for (int q = 0; q < 8; ++q) t += w[q] * Fi[off[q]];
                            if (farRow) farRow[u * strideB] = t;
                            Fr[u * strideB] = piece(vr + u * strideB * std::size_t(C)) * t;
                        }
                    }
                    for (g[b] = fastEnd; g[b] < res[b]; ++g[b]) edgePoint(g, out.index(g));
                }
            }
        };
        // Directions in fixed groups, each in parallel with its own buffers (F_k, and the far part
        // when it is not F_k itself), then added to the field point by point in k order: the
        // same sums for any thread count. Each group's terms are summed in double from the
        // field's float, so the transient memory is the groups' scalar grids, not a double
        // accumulator the size of the field twice over.
        constexpr int kGroup = kRecursiveDirectionGroup;
        const auto F = std::make_unique_for_overwrite<float[]>(std::size_t(kGroup) * P);
        const auto far =
            std::make_unique_for_overwrite<float[]>(firstPiece ? std::size_t(kGroup) * P : 0);
        for (int k0 = 0; k0 < N; k0 += kGroup) {
            const int n = std::min(kGroup, N - k0);
            arena.execute([&] {
                tbb::parallel_for(0, n, [&](int j) {
                    direction(k0 + j, F.get() + std::size_t(j) * P,
                              firstPiece ? far.get() + std::size_t(j) * P : nullptr);
                });
            });
            if (progress.cancelled()) throw CancelledError();
            const float* src = firstPiece ? far.get() : F.get();
            arena.execute([&] {
                tbb::parallel_for(tbb::blocked_range<std::size_t>(0, P), [&](const auto& range) {
                    double d[sh::kMaxCoeffs];
                    for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        float* dst = out.packed_.data() + i * S + 1;
                        for (int e = 0; e < C; ++e) d[e] = dst[e];
                        for (int j = 0; j < n; ++j) {
                            const double T = src[std::size_t(j) * P + i];
                            const double* wk = wy.data() + std::size_t(k0 + j) * C;
                            for (int e = 0; e < C; ++e) d[e] += T * wk[e];
                        }
                        for (int e = 0; e < C; ++e) dst[e] = float(d[e]);
                    }
                });
            });
            progress.report("global visibility", double(k0 + n) / N);
        }
        std::uint64_t shaded = 0;
        for (std::size_t i = 0; i < P; ++i) {
            float* dst = out.packed_.data() + i * S + 1;
            if (!needed[i]) {
                dst[0] = float(std::sqrt(4.0 * std::numbers::pi));
                std::fill(dst + 1, dst + C, 0.f);
                continue;
            }
            ++shaded;
            if (options.nearFromLocal)
                dst[-1] = std::clamp(vl[i * std::size_t(C)] * kInvSqrt4Pi, 0.f, 1.f);
        }
        out.rays_ = shaded * std::uint64_t(N);
        out.skipped_ = P - shaded;
        arena.execute([&] {
            out.pack();
            out.bake();
        });
        progress.report("global visibility", 1.0);
        return out;
    }

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
                        float* dst = out.packed_.data() + out.index(g) * S + 1;
                        const glm::vec3 x = glm::min(out.position(g), hi);
                        if (!visibilityNeeded(grid, x, spacing)) {
                            dst[0] = float(std::sqrt(4.0 * std::numbers::pi));
                            ++skipped;
                            continue;
                        }
                        if (options.nearFromLocal) {
                            local.sample(x, vl);
                            dst[-1] = std::clamp(vl[0] * kInvSqrt4Pi, 0.f, 1.f);
                        }
                        std::fill(v, v + C, 0.0);
                        for (int k = 0; k < N; ++k) {
                            // Piecewise integration in steps of r_s (eq. 11), from the second
                            // piece on when the first is the local field's.
                            const double T =
                                chain(x + float(firstPiece) * step[std::size_t(k)], k, vl);
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
    out.rays_ = raysTotal;
    out.skipped_ = skippedTotal;
    arena.execute([&] {
        out.pack();
        out.bake();
    });
    progress.report("global visibility", 1.0);
    return out;
}

std::size_t recursiveTransientBytes(const glm::ivec3& resolution, int coefficients,
                                    bool nearFromLocal) {
    const std::size_t points = std::size_t(resolution.x) * resolution.y * resolution.z;
    const std::size_t grids = std::size_t(kRecursiveDirectionGroup) * (nearFromLocal ? 2 : 1);
    return points * (std::size_t(coefficients) * sizeof(float) + 1 + grids * sizeof(float));
}

void GlobalVisibility::sample(const glm::vec3& p, float* out) const {
    if (!product_) return sampleFar(p, out);
    sample(p, out, nullptr);  // LocalVisibility::sample without the spacing: the same values
}

void GlobalVisibility::sample(const glm::vec3& p, float* out, float* spacing) const {
    VL_CHECK(baked_ != nullptr);
    baked_->sample(p, out, spacing);
}

void GlobalVisibility::sample(const FieldLookup& at, const glm::vec3& p, float* out) const {
    VL_CHECK(baked_ != nullptr);
    baked_->read(at, p, out);
}

void GlobalVisibility::pack() {
    // In place, point by point: [openness, V^F_i] → [q, q·V^F_i].
    const std::size_t S = std::size_t(coefficients_) + 1;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, packed_.size() / S),
                      [&](const auto& range) {
                          for (std::size_t i = range.begin(); i != range.end(); ++i) {
                              float* d = packed_.data() + i * S;
                              const float q = product_ ? d[0] + kBuriedWeight : 1.f;
                              d[0] = q;
                              for (std::size_t e = 1; e < S; ++e) d[e] *= q;
                          }
                      });
}

void GlobalVisibility::bake() {
    if (!product_) return;
    // V^L ⊗ V^F at the local field's points (header comment), from the packed far grid.
    const int C = coefficients_;
    baked_ =
        std::make_shared<const LocalVisibility>(local_->mapped([&](const glm::vec3& x, float* c) {
            float farV[16], v[16];
            sampleFar(x, farV);
            product_->apply(c, farV, v);
            std::copy_n(v, C, c);
        }));
}

namespace {

/// Σ_c w_c·d_c over the 8 corners, d_c = packed + off[c] (S floats each), then out = acc[1..S) /
/// acc[0]. kS > 0: S is that compile-time constant (the inner loop unrolls and vectorises);
/// kS = 0: S = runtimeS.
template <int kS>
void interpolatePacked(const float* packed, const std::size_t* off, const float* w, float* out,
                       int runtimeS = 0) {
    const int S = kS > 0 ? kS : runtimeS;
    float acc[kS > 0 ? kS : sh::kMaxCoeffs + 1] = {};
    for (int c = 0; c < 8; ++c) {
        const float* d = packed + off[c];
        for (int e = 0; e < S; ++e) acc[e] += w[c] * d[e];
    }
    const float inv = 1.f / acc[0];
    for (int e = 1; e < S; ++e) out[e - 1] = acc[e] * inv;
}

}  // namespace

void GlobalVisibility::sampleFar(const glm::vec3& p, float* out) const {
    const int C = coefficients_;
    const std::size_t S = std::size_t(C) + 1;
    glm::vec3 u = (p + 0.5f) / scale_ - 0.5f;
    u = glm::clamp(u, glm::vec3(0.f), glm::vec3(res_ - 1));
    const glm::ivec3 i0 = glm::min(glm::ivec3(u), glm::max(res_ - 2, glm::ivec3(0)));
    const glm::vec3 f = u - glm::vec3(i0);
    // Corner offsets in floats; an axis of one point reads its only point twice (weight f = 0).
    const std::size_t dx = res_.x > 1 ? S : 0, dy = res_.y > 1 ? S * res_.x : 0,
                      dz = res_.z > 1 ? S * res_.x * std::size_t(res_.y) : 0;
    const std::size_t base = index(i0) * S;
    const std::size_t off[8] = {base,      base + dx,      base + dy,      base + dx + dy,
                                base + dz, base + dx + dz, base + dy + dz, base + dx + dy + dz};
    const float wx[2] = {1.f - f.x, f.x}, wy[2] = {1.f - f.y, f.y}, wz[2] = {1.f - f.z, f.z};
    float w[8];
    for (int c = 0; c < 8; ++c) w[c] = wx[c & 1] * wy[(c >> 1) & 1] * wz[c >> 2];
    const float* d = packed_.data();
    switch (C) {
        case 1:
            return interpolatePacked<2>(d, off, w, out);
        case 4:
            return interpolatePacked<5>(d, off, w, out);
        case 9:
            return interpolatePacked<10>(d, off, w, out);
        case 16:
            return interpolatePacked<17>(d, off, w, out);
        default:
            return interpolatePacked<0>(d, off, w, out, int(S));
    }
}

}  // namespace voxlight::visibility
