// SPDX-License-Identifier: MIT
#include "visibility/hierarchical_visibility.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <numbers>
#include <thread>

#include "core/error.h"
#include "core/rng.h"
#include "core/timing.h"
#include "sh/sh_basis.h"
#include "sh/sphere_samples.h"
#include "visibility/local_visibility.h"

namespace voxlight::visibility {

namespace {

/// A rotation uniform over SO(3) from three uniforms in [0, 1) (Shoemake 1992).
glm::dquat uniformRotation(double u1, double u2, double u3) {
    constexpr double kTwoPi = 2.0 * std::numbers::pi;
    const double a = std::sqrt(1.0 - u1), b = std::sqrt(u1);
    return glm::normalize(glm::dquat(b * std::cos(kTwoPi * u3), a * std::sin(kTwoPi * u2),
                                     a * std::cos(kTwoPi * u2), b * std::sin(kTwoPi * u3)));
}

const float kSqrt4Pi = float(std::sqrt(4.0 * std::numbers::pi));
/// 8-bit code ranges: coefficient 0 unsigned, the others signed symmetric.
constexpr float kUnsignedCodes = 255.f, kSignedCodes = 127.f;

/// Trilinear interpolation of a scalar lattice of dims d at lattice coordinates u (clamped).
[[gnu::always_inline]] inline float trilinear(const float* data, const glm::ivec3& d, glm::vec3 u) {
    u = glm::clamp(u, glm::vec3(0.f), glm::vec3(d - 1));
    const int i = std::min(int(u.x), std::max(d.x - 2, 0));
    const int j = std::min(int(u.y), std::max(d.y - 2, 0));
    const int k = std::min(int(u.z), std::max(d.z - 2, 0));
    const float fx = u.x - float(i), fy = u.y - float(j), fz = u.z - float(k);
    const std::size_t di = d.x > 1 ? 1 : 0, dj = d.y > 1 ? std::size_t(d.x) : 0;
    const std::size_t dk = d.z > 1 ? std::size_t(d.x) * std::size_t(d.y) : 0;
    const float* p = data + std::size_t(i) + std::size_t(d.x) * (j + std::size_t(d.y) * k);
    const float c00 = p[0] + fx * (p[di] - p[0]);
    const float c10 = p[dj] + fx * (p[dj + di] - p[dj]);
    const float c01 = p[dk] + fx * (p[dk + di] - p[dk]);
    const float c11 = p[dk + dj] + fx * (p[dk + dj + di] - p[dk + dj]);
    const float c0 = c00 + fy * (c10 - c00), c1 = c01 + fy * (c11 - c01);
    return c0 + fz * (c1 - c0);
}

/// A ray direction in index space (index units per mm).
struct IndexRay {
    glm::vec3 d;
    IndexRay(const core::Geometry& g, const glm::dvec3& world)
        : d((glm::transpose(g.direction) * world) / g.spacing) {}
    /// Parametric exit (mm) from the box [0, dims − 1] of a ray starting inside it.
    float boxExit(const glm::vec3& o, const glm::ivec3& dims) const {
        return boxExitIndex(o, d, glm::vec3(dims - 1));
    }
};

/// Optical depth along origin + t·d, t ∈ [0, length] mm (see the header comment).
double opticalDepth(const OpacityPyramid& pyr, const glm::vec3& origin, const glm::vec3& d,
                    float length, float h, bool hierarchical, std::uint64_t& samples) {
    double tau = 0.0;
    float t = 0.f, step = h;
    int level = 0, inLevel = 0;
    const int top = pyr.levels() - 1;
    std::uint64_t n = 0;
    const optics::TfTable& table = pyr.table();
    // Level 0: the value at the front of the step and its σt integral (NaN: not read yet).
    float sFront = NAN;
    double iFront = 0.0;
    while (t < length) {
        const float dt = std::min(step, length - t);
        if (level == 0) {
            if (std::isnan(sFront)) {
                sFront = pyr.value(origin + t * d);
                iFront = table.sigmaIntegral(sFront);
            }
            const float sBack = pyr.value(origin + (t + dt) * d);
            const double iBack = table.sigmaIntegral(sBack);
            double depth = 0.0;
            if (std::isnan(sFront) || std::isnan(sBack)) {
                // A removed voxel: the clipped pyramid's midpoint read.
                depth = double(pyr.sample(0, origin + (t + 0.5f * dt) * d)) * double(dt);
            } else {
                depth = preIntegratedStep(
                    table, sFront, iFront, sBack, iBack, dt, tau,
                    [&](float x) { return pyr.value(origin + (t + x) * d); }, n);
            }
            tau += depth;
            sFront = sBack;
            iFront = iBack;
        } else {
            tau += double(pyr.sample(level, origin + (t + 0.5f * dt) * d)) * double(dt);
        }
        ++n;
        if (tau > kOpaqueDepth) break;
        t += dt;
        // Growing steps: kStepsPerLevel steps per level, then one level coarser.
        if (hierarchical && ++inLevel == kStepsPerLevel && level < top) {
            ++level;
            step *= 2.f;
            inLevel = 0;
        }
    }
    samples += n;
    return tau;
}

/// Grid points per axis of the 1:s grid.
glm::ivec3 gridResolution(const glm::ivec3& dims, int s) { return (dims - 1 + (s - 1)) / s + 1; }

/// σ_{k+1} of parent cell (x, y, z) from its children on level k (cells of L mm; header comment).
float minifyCell(const std::vector<float>& child, const glm::ivec3& dc, int x, int y, int z,
                 double L) {
    const double minMeanT = std::exp(-0.5 * kMaxCellDepth);  // T_{k+1} = mean² ≥ e^−cap
    double sum = 0.0;
    int count = 0;
    for (int k = 2 * z; k < std::min(2 * z + 2, dc.z); ++k)
        for (int j = 2 * y; j < std::min(2 * y + 2, dc.y); ++j)
            for (int i = 2 * x; i < std::min(2 * x + 2, dc.x); ++i) {
                sum += std::exp(
                    -double(
                        child[std::size_t(i) + std::size_t(dc.x) * (j + std::size_t(dc.y) * k)]) *
                    L);
                ++count;
            }
    const double meanT = std::max(sum / count, minMeanT);
    return float(-std::log(meanT) / L);
}

/// A world half-space in index space: distance(i) = dot(grad, i) + offset (mm, exact: the world
/// distance of voxel coordinate i).
struct IndexFace {
    glm::dvec3 grad;
    double offset;
    IndexFace(const core::Geometry& g, const core::HalfSpace& hs)
        : grad(g.spacing * (glm::transpose(g.direction) * hs.normal)),
          offset(glm::dot(g.origin - hs.point, hs.normal)) {}
    double distance(const glm::dvec3& i) const { return glm::dot(grad, i) + offset; }
};

std::vector<IndexFace> indexFaces(const core::Geometry& g, std::span<const core::HalfSpace> kept) {
    std::vector<IndexFace> faces;
    for (const core::HalfSpace& hs : kept) faces.emplace_back(g, hs);
    return faces;
}

}  // namespace

// ---- Opacity pyramid ---------------------------------------------------------------------------

OpacityPyramid OpacityPyramid::build(const BlockPyramid& pyramid,
                                     const optics::TransferFunction& tf,
                                     const optics::TfTable& table, const core::Progress& progress) {
    OpacityPyramid o;
    o.geometry_ = pyramid.geometry();
    const double h = core::minComponent(o.geometry_.spacing);
    const glm::ivec3 d0 = pyramid.dims();
    progress.report("opacity pyramid", 0.0);
    // Level 0: σt of every voxel (read from the block pyramid's level 0: non-finite voxels
    // already replaced there).
    o.dims_.push_back(d0);
    o.data_.emplace_back(std::size_t(o.geometry_.voxelCount()));
    o.values_.resize(o.data_.back().size());
    o.table_ = std::make_shared<const optics::TfTable>(table);
    {
        std::vector<float>& s0 = o.data_.back();
        tbb::parallel_for(tbb::blocked_range<int>(0, d0.z), [&](const auto& range) {
            for (int z = range.begin(); z != range.end(); ++z)
                for (int y = 0; y < d0.y; ++y)
                    for (int x = 0; x < d0.x; ++x) {
                        const std::size_t b =
                            pyramid.blockIndex(x / kBlockSize, y / kBlockSize, z / kBlockSize);
                        const int local =
                            x % kBlockSize +
                            kBlockSize * (y % kBlockSize + kBlockSize * (z % kBlockSize));
                        const float v = pyramid.data(b, 0)[local];
                        const std::size_t i =
                            std::size_t(x) + std::size_t(d0.x) * (y + std::size_t(d0.y) * z);
                        s0[i] = table.extinction(v);
                        o.values_[i] = v;
                    }
        });
    }
    // Coarser levels: σ_{k+1} = −ln(mean of the children's T_k) / L_k (header comment).
    double L = h;
    while (o.dims_.back() != glm::ivec3(1)) {
        const glm::ivec3 dc = o.dims_.back();
        const glm::ivec3 dp = (dc + 1) / 2;
        std::vector<float> parent(std::size_t(dp.x) * dp.y * dp.z);
        const std::vector<float>& child = o.data_.back();
        tbb::parallel_for(tbb::blocked_range<int>(0, dp.z), [&](const auto& range) {
            for (int z = range.begin(); z != range.end(); ++z)
                for (int y = 0; y < dp.y; ++y)
                    for (int x = 0; x < dp.x; ++x)
                        parent[std::size_t(x) + std::size_t(dp.x) * (y + std::size_t(dp.y) * z)] =
                            minifyCell(child, dc, x, y, z, L);
        });
        o.dims_.push_back(dp);
        o.data_.push_back(std::move(parent));
        L *= 2.0;
    }
    o.cellVisible_ = visibleCells(pyramid, tf, table);
    o.cells_ = pyramid.cells();
    o.visibleCounts_ = VisibleCellCounts(o.cells_, o.cellVisible_);
    progress.report("opacity pyramid", 1.0);
    return o;
}

OpacityPyramid OpacityPyramid::withRemoved(std::span<const core::HalfSpace> kept,
                                           std::uint64_t* voxelsChanged,
                                           std::uint64_t* cellsChanged) const {
    OpacityPyramid o = *this;
    std::uint64_t voxels = 0, cells = 0;
    if (!kept.empty()) {
        const std::vector<IndexFace> faces = indexFaces(geometry_, kept);
        // Level 0: each voxel's σt times the fraction of it each half-space keeps — the voxel's
        // box (±½ voxel, cut to the volume's box [0, dims − 1], where the rays end: a plane on
        // the outermost centres keeps everything) as a slab across the plane's normal, kept =
        // ½ + distance of the box's centre / its width, clamped — so a moving plane thins a voxel
        // continuously. (All or nothing by the centre made a cut face jump ≈ 10 % in brightness
        // each time the plane crossed a voxel centre: probe.) A voxel any plane touches reads
        // its σt, not its value (NaN); fully removed ones are counted.
        const glm::ivec3 d0 = dims_[0];
        std::vector<std::uint8_t> changed(o.data_[0].size(), 0);
        // The voxel's box along one axis: its centre and half-width (index units).
        const auto span = [](int i, int n) {
            const double lo = std::max(i - 0.5, 0.0), hi = std::min(i + 0.5, n - 1.0);
            return glm::dvec2(0.5 * (lo + hi), 0.5 * (hi - lo));
        };
        std::atomic<std::uint64_t> zeroed{0};
        tbb::parallel_for(tbb::blocked_range<int>(0, d0.z), [&](const auto& range) {
            std::uint64_t n = 0;
            for (int z = range.begin(); z != range.end(); ++z)
                for (int y = 0; y < d0.y; ++y)
                    for (int x = 0; x < d0.x; ++x) {
                        const std::size_t i =
                            std::size_t(x) + std::size_t(d0.x) * (y + std::size_t(d0.y) * z);
                        if (o.data_[0][i] == 0.f) continue;
                        const glm::dvec2 sx = span(x, d0.x), sy = span(y, d0.y), sz = span(z, d0.z);
                        const glm::dvec3 c(sx[0], sy[0], sz[0]), half(sx[1], sy[1], sz[1]);
                        double keep = 1.0;
                        for (std::size_t k = 0; k < faces.size() && keep > 0.0; ++k) {
                            const IndexFace& f = faces[k];
                            const double d = f.distance(c),
                                         w = 2.0 * glm::dot(glm::abs(f.grad), half);
                            keep *= w > 0.0 ? std::clamp(0.5 + d / w, 0.0, 1.0) : d >= 0.0;
                        }
                        if (keep >= 1.0) continue;
                        o.data_[0][i] = keep > 0.0 ? float(keep * o.data_[0][i]) : 0.f;
                        o.values_[i] = NAN;
                        changed[i] = 1;
                        n += keep <= 0.0;
                    }
            zeroed += n;
        });
        voxels = zeroed;
        // Coarser levels: a parent changes only when a child did; minify those again.
        double L = core::minComponent(geometry_.spacing);
        for (std::size_t l = 1; l < o.data_.size() && voxels > 0; ++l) {
            const glm::ivec3 dc = dims_[l - 1], dp = dims_[l];
            std::vector<std::uint8_t> parentChanged(o.data_[l].size(), 0);
            std::atomic<std::uint64_t> redone{0};
            tbb::parallel_for(tbb::blocked_range<int>(0, dp.z), [&](const auto& range) {
                std::uint64_t n = 0;
                for (int z = range.begin(); z != range.end(); ++z)
                    for (int y = 0; y < dp.y; ++y)
                        for (int x = 0; x < dp.x; ++x) {
                            bool any = false;
                            for (int k = 2 * z; k < std::min(2 * z + 2, dc.z) && !any; ++k)
                                for (int j = 2 * y; j < std::min(2 * y + 2, dc.y) && !any; ++j)
                                    for (int i = 2 * x; i < std::min(2 * x + 2, dc.x) && !any; ++i)
                                        any = changed[std::size_t(i) +
                                                      std::size_t(dc.x) *
                                                          (j + std::size_t(dc.y) * k)] != 0;
                            if (!any) continue;
                            const std::size_t p =
                                std::size_t(x) + std::size_t(dp.x) * (y + std::size_t(dp.y) * z);
                            o.data_[l][p] = minifyCell(o.data_[l - 1], dc, x, y, z, L);
                            parentChanged[p] = 1;
                            ++n;
                        }
                redone += n;
            });
            cells += redone;
            changed = std::move(parentChanged);
            L *= 2.0;
        }
    }
    if (voxelsChanged) *voxelsChanged = voxels;
    if (cellsChanged) *cellsChanged = cells;
    return o;
}

float OpacityPyramid::sample(int level, const glm::vec3& p) const {
    const float inv = 1.f / float(1 << level);  // exact: a power of two
    return trilinear(data_[std::size_t(level)].data(), dims_[std::size_t(level)],
                     (p + 0.5f) * inv - 0.5f);
}

float OpacityPyramid::value(const glm::vec3& p) const {
    return trilinear(values_.data(), dims_[0], p);
}

std::size_t OpacityPyramid::bytes() const {
    std::size_t b = cellVisible_.size() + visibleCounts_.bytes() + values_.size() * sizeof(float);
    for (const auto& l : data_) b += l.size() * sizeof(float);
    return b;
}

// ---- Visibility field --------------------------------------------------------------------------

void checkHierarchicalOptions(const HierarchicalVisibilityOptions& o) {
    const char* src = "hierarchical visibility";
    if (o.coefficients != 1 && o.coefficients != 4 && o.coefficients != 9 && o.coefficients != 16)
        throw InputError(src, "coefficients",
                         "must be 1, 4, 9 or 16, got " + std::to_string(o.coefficients),
                         "choose 1 (ambient occlusion), 4, 9 or 16");
    if (o.rays < kMinRaysPerCoefficient * o.coefficients || o.rays > 65536)
        throw InputError(src, "rays",
                         "must be in [" + std::to_string(kMinRaysPerCoefficient * o.coefficients) +
                             ", 65536] for " + std::to_string(o.coefficients) +
                             " coefficients, got " + std::to_string(o.rays),
                         "use more rays or fewer coefficients");
    if (o.patterns < 1 || o.patterns > kMaxPatterns)
        throw InputError(src, "patterns",
                         "must be in [1, " + std::to_string(kMaxPatterns) + "], got " +
                             std::to_string(o.patterns),
                         "give e.g. 16");
    if (o.subsample < 1 || o.subsample > kMaxSubsample)
        throw InputError(src, "subsample",
                         "must be in [1, " + std::to_string(kMaxSubsample) + "], got " +
                             std::to_string(o.subsample),
                         "give 1 (every voxel), 2, 4 or 8");
    if (!(o.maxDistanceVoxels > 0.0))
        throw InputError(src, "max_distance", "must be a number of voxels > 0",
                         "give e.g. 64, or leave it out to reach the volume's boundary");
}

/// The field on `pyr` (computeHierarchicalVisibility), with the grid points more than
/// (s + 1)·|spacing| mm outside some half-space of `kept` cleared to empty space's value without
/// rays (clipAwareHierarchicalVisibility); `cleared` (optional) counts them.
HierarchicalVisibility computeField(const OpacityPyramid& pyr,
                                    const HierarchicalVisibilityOptions& options,
                                    std::span<const core::HalfSpace> kept,
                                    const core::Progress& progress, std::uint64_t* cleared) {
    checkHierarchicalOptions(options);
    const int C = options.coefficients, N = options.rays, M = options.patterns;
    const int s = options.subsample;
    const core::Geometry& g = pyr.geometry();
    const glm::ivec3 dims = g.dims;
    const float h = float(core::minComponent(g.spacing));
    const float maxLength = float(std::min(options.maxDistanceVoxels * h, 1e30));
    // Never read by a shaded sample beyond this distance outside a face (header comment); one
    // voxel more than a 1:s cell's diagonal, for samples a rounding error outside.
    const std::vector<IndexFace> faces = indexFaces(g, kept);
    const double clearBeyond = double(s + 1) * glm::length(g.spacing);

    // The M jittered patterns: index-space directions and w_k·Y_i(ω_k) per direction.
    std::vector<IndexRay> rays;
    std::vector<double> wy(std::size_t(M) * N * C);
    std::vector<double> y(static_cast<std::size_t>(sh::kMaxCoeffs));
    for (int m = 0; m < M; ++m) {
        sh::SphereSamples dirs = sh::jitteredSamples(N, options.seed, std::uint64_t(m));
        if (!tryCorrectVisibilityWeights(dirs, C)) {
            // Too uneven for a positive correction (few rays per coefficient, e.g. 32 for 16):
            // the Fibonacci set under a random rotation instead. Its corrected weights are
            // positive (sh-local's own set) and stay so under any rotation, since the constraints
            // span whole SH bands, which rotations map onto themselves.
            dirs = sh::fibonacciSamples(N);
            core::CounterRng rng(core::hashCounters(std::uint64_t(m), std::uint64_t(N), 0x524f54u),
                                 options.seed);
            const glm::dquat q =
                uniformRotation(rng.uniformDouble(), rng.uniformDouble(), rng.uniformDouble());
            for (auto& d : dirs.directions) d = q * d;
            correctVisibilityWeights(dirs, C);
        }
        for (int k = 0; k < N; ++k) {
            rays.emplace_back(g, dirs.directions[std::size_t(k)]);
            sh::evalShUnitDouble(sh::shBandForCount(C), dirs.directions[std::size_t(k)], y);
            for (int i = 0; i < C; ++i)
                wy[(std::size_t(m) * N + k) * C + i] =
                    dirs.weights[std::size_t(k)] * y[std::size_t(i)];
        }
    }

    HierarchicalVisibility out;
    out.coefficients_ = C;
    out.rays_ = N;
    out.patterns_ = M;
    out.subsample_ = s;
    out.res_ = gridResolution(dims, s);
    const glm::ivec3 res = out.res_;
    const std::size_t points = std::size_t(res.x) * res.y * res.z;
    out.data_.assign(points * C, 0.f);

    std::atomic<std::uint64_t> samplesTotal{0}, raysTotal{0}, skippedTotal{0}, clearedTotal{0};
    std::atomic<int> done{0};
    const std::thread::id caller = std::this_thread::get_id();
    progress.report("hierarchical visibility", 0.0);
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
    arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<int>(0, res.z, 1), [&](const auto& range) {
            if (progress.cancelled()) return;
            std::uint64_t samples = 0, traced = 0, skipped = 0, outside = 0;
            double v[16];
            for (int gz = range.begin(); gz != range.end(); ++gz) {
                for (int gy = 0; gy < res.y; ++gy)
                    for (int gx = 0; gx < res.x; ++gx) {
                        const glm::ivec3 gp(gx, gy, gz);
                        const std::size_t idx = out.index(gp);
                        float* dst = out.data_.data() + idx * C;
                        const glm::vec3 origin(glm::min(gp * s, dims - 1));
                        if (!visibilityNeeded(pyr.visibleCellCounts(), origin, float(s))) {
                            // Never read by a shaded sample: empty space's value.
                            dst[0] = kSqrt4Pi;
                            ++skipped;
                            continue;
                        }
                        if (std::any_of(faces.begin(), faces.end(), [&](const IndexFace& f) {
                                return f.distance(glm::dvec3(origin)) < -clearBeyond;
                            })) {
                            // Far on the removed side: never read either.
                            dst[0] = kSqrt4Pi;
                            ++outside;
                            continue;
                        }
                        // This point's pattern: neighbours use different directions.
                        const int m = int(core::hashCounters(idx, 0x726974u, 0, options.seed) %
                                          std::uint64_t(M));
                        std::fill(v, v + C, 0.0);
                        for (int k = 0; k < N; ++k) {
                            const IndexRay& ray = rays[std::size_t(m) * N + k];
                            const float length = std::min(maxLength, ray.boxExit(origin, dims));
                            const double tau = opticalDepth(pyr, origin, ray.d, length, h,
                                                            options.hierarchical, samples);
                            // Project this direction's transmittance onto the SH basis.
                            const double T = std::exp(-tau);
                            const double* w = wy.data() + (std::size_t(m) * N + k) * C;
                            for (int c = 0; c < C; ++c) v[c] += T * w[c];
                        }
                        traced += std::uint64_t(N);
                        for (int c = 0; c < C; ++c) dst[c] = float(v[c]);
                    }
            }
            samplesTotal += samples;
            raysTotal += traced;
            skippedTotal += skipped;
            clearedTotal += outside;
            const int now = done.fetch_add(int(range.size())) + int(range.size());
            if (std::this_thread::get_id() == caller)  // workers only stop taking slices
                progress.report("hierarchical visibility", double(now) / double(res.z));
        });
    });
    if (progress.cancelled()) throw CancelledError();
    out.samplesTaken_ = samplesTotal;
    out.raysTraced_ = raysTotal;
    out.pointsSkipped_ = skippedTotal;
    if (cleared) *cleared = clearedTotal;

    if (options.quantize8) {
        // One scale per coefficient from the largest magnitude (header comment).
        std::vector<float> maxAbs(std::size_t(C), 0.f);
        for (std::size_t p = 0; p < points; ++p)
            for (int c = 0; c < C; ++c)
                maxAbs[std::size_t(c)] =
                    std::max(maxAbs[std::size_t(c)], std::abs(out.data_[p * C + c]));
        out.scale_.resize(std::size_t(C));
        for (int c = 0; c < C; ++c)
            out.scale_[std::size_t(c)] =
                maxAbs[std::size_t(c)] > 0.f
                    ? maxAbs[std::size_t(c)] / (c == 0 ? kUnsignedCodes : kSignedCodes)
                    : 1.f;
        out.q_.resize(points * C);
        for (std::size_t p = 0; p < points; ++p)
            for (int c = 0; c < C; ++c) {
                const float q = std::round(out.data_[p * C + c] / out.scale_[std::size_t(c)]);
                out.q_[p * C + c] =
                    c == 0 ? std::uint8_t(std::clamp(q, 0.f, kUnsignedCodes))
                           : std::uint8_t(std::int8_t(std::clamp(q, -kSignedCodes, kSignedCodes)));
            }
        std::vector<float>().swap(out.data_);
    }
    progress.report("hierarchical visibility", 1.0);
    return out;
}

HierarchicalVisibility computeHierarchicalVisibility(std::shared_ptr<const OpacityPyramid> pyramid,
                                                     const HierarchicalVisibilityOptions& options,
                                                     const core::Progress& progress) {
    VL_CHECK(pyramid != nullptr);
    return computeField(*pyramid, options, {}, progress, nullptr);
}

HierarchicalVisibility clipAwareHierarchicalVisibility(const OpacityPyramid& base,
                                                       std::span<const core::HalfSpace> kept,
                                                       const HierarchicalVisibilityOptions& options,
                                                       const core::Progress& progress,
                                                       HierarchicalClipStats* stats) {
    checkHierarchicalOptions(options);
    HierarchicalClipStats st;
    core::Stopwatch clock;
    progress.report("clip-aware opacity pyramid", 0.0);
    const OpacityPyramid clipped = base.withRemoved(kept, &st.voxelsRemoved, &st.cellsChanged);
    st.pyramidSeconds = clock.seconds();
    progress.report("clip-aware opacity pyramid", 1.0);
    core::Stopwatch rays;
    HierarchicalVisibility out = computeField(clipped, options, kept, progress, &st.pointsCleared);
    st.visibilitySeconds = rays.seconds();
    const glm::ivec3 r = out.resolution();
    st.points = std::uint64_t(r.x) * std::uint64_t(r.y) * std::uint64_t(r.z);
    st.pointsSkipped = out.pointsSkipped();
    st.pointsTraced = st.points - st.pointsSkipped - st.pointsCleared;
    st.raysTraced = out.raysTraced();
    if (stats) *stats = st;
    return out;
}

void HierarchicalVisibility::at(const glm::ivec3& g, float* out) const {
    const int C = coefficients_;
    const std::size_t base = index(g) * std::size_t(C);
    if (q_.empty()) {
        std::copy(data_.begin() + std::ptrdiff_t(base), data_.begin() + std::ptrdiff_t(base + C),
                  out);
        return;
    }
    out[0] = float(q_[base]) * scale_[0];
    for (int c = 1; c < C; ++c)
        out[c] = float(std::int8_t(q_[base + std::size_t(c)])) * scale_[std::size_t(c)];
}

void HierarchicalVisibility::sample(const glm::vec3& p, float* out) const {
    const int C = coefficients_;
    const glm::vec3 u =
        glm::clamp(p * (1.f / float(subsample_)), glm::vec3(0.f), glm::vec3(res_ - 1));
    const glm::ivec3 i0 = glm::min(glm::ivec3(u), glm::max(res_ - 2, glm::ivec3(0)));
    const glm::vec3 f = u - glm::vec3(i0);
    const glm::ivec3 i1 = glm::min(i0 + 1, res_ - 1);
    std::fill(out, out + C, 0.f);
    float corner[16];
    for (int k = 0; k < 8; ++k) {
        const glm::ivec3 c((k & 1) ? i1.x : i0.x, (k & 2) ? i1.y : i0.y, (k & 4) ? i1.z : i0.z);
        const float w =
            ((k & 1) ? f.x : 1.f - f.x) * ((k & 2) ? f.y : 1.f - f.y) * ((k & 4) ? f.z : 1.f - f.z);
        if (w == 0.f) continue;
        at(c, corner);
        for (int i = 0; i < C; ++i) out[i] += w * corner[i];
    }
}

double hierarchicalTransmittance(const OpacityPyramid& pyramid, const glm::vec3& origin,
                                 const glm::dvec3& dir, double maxDistanceVoxels, bool hierarchical,
                                 std::uint64_t* samples) {
    const core::Geometry& g = pyramid.geometry();
    const float h = float(core::minComponent(g.spacing));
    const IndexRay ray(g, dir);
    const float length =
        std::min(float(std::min(maxDistanceVoxels * h, 1e30)), ray.boxExit(origin, g.dims));
    std::uint64_t n = 0;
    const double tau = opticalDepth(pyramid, origin, ray.d, length, h, hierarchical, n);
    if (samples) *samples += n;
    return std::exp(-tau);
}

}  // namespace voxlight::visibility
