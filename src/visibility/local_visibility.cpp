// SPDX-License-Identifier: MIT
#include "visibility/local_visibility.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <Eigen/Dense>
#include <atomic>
#include <cmath>
#include <numbers>
#include <thread>

#include "core/error.h"
#include "sh/sh_basis.h"

namespace voxlight::visibility {

namespace {

void checkOptions(const LocalVisibilityOptions& o) {
    if (o.coefficients != 1 && o.coefficients != 4 && o.coefficients != 9 && o.coefficients != 16)
        throw InputError("local visibility", "coefficients",
                         "must be 1, 4, 9 or 16, got " + std::to_string(o.coefficients),
                         "choose 1 (ambient occlusion), 4, 9 or 16");
    if (o.rays < kMinRaysPerCoefficient * o.coefficients || o.rays > 65536)
        throw InputError("local visibility", "rays",
                         "must be in [" + std::to_string(kMinRaysPerCoefficient * o.coefficients) +
                             ", 65536] for " + std::to_string(o.coefficients) +
                             " coefficients, got " + std::to_string(o.rays),
                         "use more rays or fewer coefficients");
    if (!(o.radiusVoxels > 0.0) || !std::isfinite(o.radiusVoxels))
        throw InputError("local visibility", "radius", "must be a finite number of voxels > 0",
                         "give e.g. 16");
}

/// Parametric exit (mm) of the ray origin + t·dir from the box [0, d − 1] it starts in.
double boxExit(const glm::vec3& origin, const glm::dvec3& dirIndex, const glm::ivec3& d) {
    double t = INFINITY;
    for (int a = 0; a < 3; ++a) {
        if (dirIndex[a] > 0.0)
            t = std::min(t, (double(d[a] - 1) - origin[a]) / dirIndex[a]);
        else if (dirIndex[a] < 0.0)
            t = std::min(t, -double(origin[a]) / dirIndex[a]);
    }
    return std::max(t, 0.0);
}

/// σt at every stored sample of the selection (pre-classified: the TF applied to each block's
/// selected-level samples), laid out like MultiresGrid::levelData.
struct SigmaField {
    const MultiresGrid& grid;
    std::vector<float> sigma;
    std::vector<const float*> block;  ///< per block, nullptr at kNone

    SigmaField(const MultiresGrid& g, const optics::TfTable& table) : grid(g) {
        const std::size_t n = g.pyramid().blockCount();
        std::vector<std::size_t> offset(n, 0);
        std::size_t total = 0;
        for (std::size_t b = 0; b < n; ++b) {
            offset[b] = total;
            if (g.level(b) != kNone) total += std::size_t(std::pow(levelResolution(g.level(b)), 3));
        }
        sigma.resize(total);
        block.assign(n, nullptr);
        for (std::size_t b = 0; b < n; ++b) {
            const int l = g.level(b);
            if (l == kNone) continue;
            const std::size_t m = std::size_t(std::pow(levelResolution(l), 3));
            const float* v = g.levelData(b);
            for (std::size_t i = 0; i < m; ++i) sigma[offset[b] + i] = table.extinction(v[i]);
            block[b] = sigma.data() + offset[b];
        }
    }

    /// σt at p from the block that owns p alone, clamped to its sample box; level of that block
    /// (kNone: σt 0).
    [[gnu::always_inline]] float at(const glm::vec3& p, int& level) const {
        const glm::ivec3 b = grid.ownerCoord(p);
        const std::size_t idx = grid.indexOf(b);
        level = grid.level(idx);
        if (level == kNone) return 0.f;
        const int n = levelResolution(level);
        const float top = float(n - 1);
        const glm::vec3 u = glm::clamp(
            (p - (glm::vec3(b) * float(kBlockSize) - 0.5f)) / float(levelSpacing(level)) - 0.5f,
            glm::vec3(0.f), glm::vec3(top));
        float v = 0.f;
        addTrilinear(block[idx], n, 1, u, 1.f, &v);
        return v;
    }
};

/// The march of rayTransmittance with the index-space direction and step length precomputed.
/// Returns the optical depth.
double opticalDepth(const SigmaField& field, const glm::vec3& origin, const glm::dvec3& dirIndex,
                    double lengthMm, double voxelMm, std::uint64_t& samples) {
    double tau = 0.0;
    float t = 0.f;
    const float length = float(lengthMm), h = float(voxelMm);
    const glm::vec3 d(dirIndex);
    std::uint64_t n = 0;
    const MultiresGrid& grid = field.grid;
    while (t < length) {
        const int level = grid.level(grid.ownerBlock(origin + t * d));
        const float stepVoxels =
            level == kNone ? kMaxStepVoxels : std::min(float(levelSpacing(level)), kMaxStepVoxels);
        const float dt = std::min(stepVoxels * h, length - t);
        int at = kNone;
        const float sigma = field.at(origin + (t + 0.5f * dt) * d, at);
        if (at != kNone) {
            ++n;
            tau += double(sigma) * double(dt);
            if (tau > kOpaqueDepth) break;
        }
        t += dt;
    }
    samples += n;
    return tau;
}

}  // namespace

sh::SphereSamples visibilityDirections(int rays, int coefficients) {
    LocalVisibilityOptions o;
    o.rays = rays;
    o.coefficients = coefficients;
    checkOptions(o);
    sh::SphereSamples s = sh::fibonacciSamples(rays);
    // Minimum-norm change of the weights so that Σ_k w_k Y_i(ω_k) = √(4π) δ_i0 for i < C:
    // w = w0 + Aᵀ (A Aᵀ)⁻¹ (b − A w0), A_ik = Y_i(ω_k).
    const int n = rays, c = coefficients;
    Eigen::MatrixXd A(c, n);
    std::vector<double> y(std::size_t(sh::kMaxCoeffs));
    for (int k = 0; k < n; ++k) {
        sh::evalShUnitDouble(sh::shBandForCount(c), s.directions[std::size_t(k)], y);
        for (int i = 0; i < c; ++i) A(i, k) = y[std::size_t(i)];
    }
    Eigen::VectorXd w0(n);
    for (int k = 0; k < n; ++k) w0(k) = s.weights[std::size_t(k)];
    Eigen::VectorXd b = Eigen::VectorXd::Zero(c);
    b(0) = std::sqrt(4.0 * std::numbers::pi);
    const Eigen::MatrixXd gram = A * A.transpose();
    const Eigen::VectorXd w = w0 + A.transpose() * gram.ldlt().solve(b - A * w0);
    for (int k = 0; k < n; ++k) {
        if (!(w(k) > 0.0))
            throw InternalError("visibility weight " + std::to_string(k) + " of " +
                                std::to_string(n) + " rays is not positive (" +
                                std::to_string(w(k)) + ")");
        s.weights[std::size_t(k)] = w(k);
    }
    return s;
}

double rayTransmittance(const MultiresGrid& grid, const optics::TfTable& table,
                        const glm::vec3& origin, const glm::dvec3& dir, double radiusVoxels,
                        std::uint64_t* samples) {
    const core::Geometry& g = grid.pyramid().geometry();
    const double h = core::minComponent(g.spacing);
    const glm::dvec3 dirIndex = (glm::transpose(g.direction) * dir) / g.spacing;
    const double length = std::min(radiusVoxels * h, boxExit(origin, dirIndex, grid.dims()));
    std::uint64_t n = 0;
    const SigmaField field(grid, table);
    const double tau = opticalDepth(field, origin, dirIndex, length, h, n);
    if (samples) *samples += n;
    return std::exp(-tau);
}

LocalVisibility computeLocalVisibility(std::shared_ptr<const MultiresGrid> gridPtr,
                                       const optics::TfTable& table,
                                       const LocalVisibilityOptions& options,
                                       const core::Progress& progress) {
    checkOptions(options);
    VL_CHECK(gridPtr != nullptr);
    const MultiresGrid& grid = *gridPtr;
    const sh::SphereSamples dirs = visibilityDirections(options.rays, options.coefficients);
    const int C = options.coefficients, N = options.rays;
    const core::Geometry& g = grid.pyramid().geometry();
    const double h = core::minComponent(g.spacing);

    // Per direction: index-space direction and w_k·Y_i(ω_k).
    std::vector<glm::dvec3> dirIndex(static_cast<std::size_t>(N));
    std::vector<double> wy(std::size_t(N) * C);
    std::vector<double> y(std::size_t(sh::kMaxCoeffs));
    for (int k = 0; k < N; ++k) {
        dirIndex[std::size_t(k)] =
            (glm::transpose(g.direction) * dirs.directions[std::size_t(k)]) / g.spacing;
        sh::evalShUnitDouble(sh::shBandForCount(C), dirs.directions[std::size_t(k)], y);
        for (int i = 0; i < C; ++i)
            wy[std::size_t(k) * C + i] = dirs.weights[std::size_t(k)] * y[std::size_t(i)];
    }

    const SigmaField sigma(grid, table);
    LocalVisibility out;
    out.grid_ = gridPtr;
    out.coefficients_ = C;
    out.rays_ = N;
    out.radius_ = options.radiusVoxels;
    const std::size_t blocks = grid.pyramid().blockCount();
    out.offset_.assign(blocks, 0);
    std::vector<std::size_t> stored;
    std::size_t floats = 0;
    for (std::size_t b = 0; b < blocks; ++b) {
        const int l = grid.level(b);
        if (l == kNone) continue;
        out.offset_[b] = floats;
        const std::size_t n = std::size_t(levelResolution(l));
        floats += n * n * n * std::size_t(C);
        stored.push_back(b);
    }
    out.data_.assign(floats, 0.f);

    std::atomic<std::uint64_t> samplesTotal{0}, raysTotal{0};
    std::atomic<std::size_t> done{0};
    const std::thread::id caller = std::this_thread::get_id();
    progress.report("local visibility", 0.0);
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
    arena.execute([&] {
        tbb::parallel_for(
            tbb::blocked_range<std::size_t>(0, stored.size(), 1), [&](const auto& range) {
                if (progress.cancelled()) return;
                std::uint64_t samples = 0, rays = 0;
                double v[16];
                for (std::size_t r = range.begin(); r != range.end(); ++r) {
                    const std::size_t b = stored[r];
                    const int l = grid.level(b);
                    const int n = levelResolution(l);
                    float* dst = out.data_.data() + out.offset_[b];
                    for (int k = 0; k < n; ++k)
                        for (int j = 0; j < n; ++j)
                            for (int i = 0; i < n; ++i, dst += C) {
                                const glm::vec3 x = grid.samplePosition(b, l, i, j, k);
                                // Sample points of a partial edge block beyond the volume are clamped
                                // onto it (their values are never read inside the volume).
                                const glm::vec3 origin = glm::min(x, glm::vec3(grid.dims() - 1));
                                std::fill(v, v + C, 0.0);
                                for (int d = 0; d < N; ++d) {
                                    const glm::dvec3& di = dirIndex[std::size_t(d)];
                                    const double length = std::min(
                                        options.radiusVoxels * h, boxExit(origin, di, grid.dims()));
                                    const double tau =
                                        opticalDepth(sigma, origin, di, length, h, samples);
                                    // Project this direction's transmittance onto the SH basis.
                                    const double T = std::exp(-tau);
                                    const double* w = wy.data() + std::size_t(d) * C;
                                    for (int c = 0; c < C; ++c) v[c] += T * w[c];
                                }
                                rays += std::uint64_t(N);
                                for (int c = 0; c < C; ++c) dst[c] = float(v[c]);
                            }
                }
                samplesTotal += samples;
                raysTotal += rays;
                const std::size_t now = done.fetch_add(range.size()) + range.size();
                if (std::this_thread::get_id() == caller)  // workers only stop taking blocks
                    progress.report("local visibility", double(now) / double(stored.size()));
            });
    });
    if (progress.cancelled()) throw CancelledError();
    progress.report("local visibility", 1.0);
    out.samplesTaken_ = samplesTotal;
    out.raysTraced_ = raysTotal;
    return out;
}

void LocalVisibility::sample(const glm::vec3& p, float* out) const {
    const int C = coefficients_;
    std::fill(out, out + C, 0.f);
    BlockWeights w;
    grid_->weights(p, w);
    if (w.count == 0) {
        out[0] = float(std::sqrt(4.0 * std::numbers::pi));
        return;
    }
    for (int k = 0; k < w.count; ++k)
        addTrilinear(blockData(w.block[k]), levelResolution(w.level[k]), C, w.local[k], w.weight[k],
                     out);
}

}  // namespace voxlight::visibility
