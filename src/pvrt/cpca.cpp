// SPDX-License-Identifier: MIT
// Eigen's own threads (OpenMP) would bypass the oneTBB arena and our fixed-order reductions.
#define EIGEN_DONT_PARALLELIZE
#include "pvrt/cpca.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <ostream>
#include <string>

#include "core/error.h"
#include "core/rng.h"

namespace voxlight::pvrt {

namespace {

/// Rows per block of every row-parallel loop: the unit of work and of partial sums, fixed so that
/// the result does not depend on the thread count.
constexpr std::size_t kBlockRows = 1024;
/// PCA clusters per progress report (the reports come from the calling thread between batches).
constexpr int kPcaBatch = 16;

using RowMatrixF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using ConstRowsF = Eigen::Map<const RowMatrixF>;

struct Blocks {
    std::size_t rows = 0;
    std::size_t count() const { return (rows + kBlockRows - 1) / kBlockRows; }
    std::size_t begin(std::size_t b) const { return b * kBlockRows; }
    std::size_t end(std::size_t b) const { return std::min(rows, (b + 1) * kBlockRows); }
};

/// f(block, begin, end) for every block, in parallel; each block is one task.
template <class F>
void forEachBlock(const Blocks& blocks, const core::Progress& progress, F&& f) {
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, blocks.count(), 1),
        [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t b = r.begin(); b != r.end(); ++b) {
                progress.checkCancel();
                f(b, blocks.begin(b), blocks.end(b));
            }
        },
        tbb::simple_partitioner());
}

/// f(i) for i in [0, n), one task per index.
template <class F>
void forEachIndex(int begin, int end, F&& f) {
    tbb::parallel_for(
        tbb::blocked_range<int>(begin, end, 1),
        [&](const tbb::blocked_range<int>& r) {
            for (int i = r.begin(); i != r.end(); ++i) f(i);
        },
        tbb::simple_partitioner());
}

void checkOptions(const CpcaOptions& o) {
    auto refuse = [](const char* name, int value, const char* fix) {
        throw InputError("pvrt", std::string("cpca.") + name,
                         std::to_string(value) + " is out of range", fix);
    };
    if (o.clusters < 1) refuse("clusters", o.clusters, "use at least 1 cluster (128 is typical)");
    if (o.components < 0)
        refuse("components", o.components, "use 0 or more components (4 is typical)");
    if (o.iterations < 0) refuse("iterations", o.iterations, "use 0 or more Lloyd iterations");
    if (o.threads < 0) refuse("threads", o.threads, "use 0 (all hardware threads) or more");
}

void checkFinite(std::span<const float> rows, int dim, const core::Progress& progress) {
    const Blocks blocks{rows.size() / std::size_t(dim)};
    std::vector<std::size_t> firstBad(blocks.count(), rows.size());
    forEachBlock(blocks, progress, [&](std::size_t b, std::size_t begin, std::size_t end) {
        for (std::size_t i = begin * dim; i < end * dim; ++i)
            if (!std::isfinite(rows[i])) {
                firstBad[b] = i;
                return;
            }
    });
    for (const std::size_t i : firstBad)
        if (i < rows.size())
            throw InputError(
                "pvrt",
                "transfer[" + std::to_string(i / dim) + "][" + std::to_string(i % dim) + "]",
                "is " + std::to_string(rows[i]) + ", not a finite number",
                "the transfer precompute produced NaN or infinity; compress only "
                "finite transfer rows");
}

// ---- k-means -----------------------------------------------------------------------------------

struct KMeans {
    const float* data = nullptr;
    int dim = 0;
    Blocks blocks;
    int k = 0;
    std::vector<float> centres;       ///< k × dim
    std::vector<std::int32_t> label;  ///< per row
    std::vector<float> dist;          ///< per row: squared distance to its centre
    std::vector<float> norm2;         ///< per row: |x|²

    const float* row(std::size_t i) const { return data + i * std::size_t(dim); }
};

float squaredDistance(const float* a, const float* b, int dim) {
    return (Eigen::Map<const Eigen::VectorXf>(a, dim) - Eigen::Map<const Eigen::VectorXf>(b, dim))
        .squaredNorm();
}

/// Relative slack on the triangle-inequality test that lets k-means++ seeding skip a row.
constexpr float kSeedSkipMargin = 1.001f;

/// k-means++ seeding (D² sampling) from `seed`; stops early when every row coincides with a seed.
/// Leaves each row's nearest seed in km.label and its squared distance in km.dist.
void seedKMeansPlusPlus(KMeans& km, int clusters, std::uint64_t seed,
                        const core::Progress& progress) {
    const std::size_t n = km.blocks.rows;
    auto addCentre = [&](std::size_t i) {
        km.centres.insert(km.centres.end(), km.row(i), km.row(i) + km.dim);
        ++km.k;
    };
    const std::size_t first =
        std::min(n - 1, std::size_t(core::toUnitDouble(core::hashCounters(0, 0, 0, seed)) * n));
    addCentre(first);
    std::vector<float>& d2 = km.dist;
    d2.assign(n, 0.f);
    std::vector<double> blockSum(km.blocks.count());
    forEachBlock(km.blocks, progress, [&](std::size_t, std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            d2[i] = squaredDistance(km.row(i), km.row(first), km.dim);
            km.label[i] = 0;
        }
    });
    std::vector<float> between;  // |c_t − c_a|² for the newest centre t and every a < t
    for (int t = 1; t < clusters; ++t) {
        // Sample a row with probability ∝ D²: block sums in block order, then a scan in the block.
        forEachBlock(km.blocks, progress, [&](std::size_t b, std::size_t begin, std::size_t end) {
            double s = 0;
            for (std::size_t i = begin; i < end; ++i) s += d2[i];
            blockSum[b] = s;
        });
        double total = 0;
        for (const double s : blockSum) total += s;
        if (!(total > 0)) break;  // every row is a seed already
        const double target =
            core::toUnitDouble(core::hashCounters(std::uint64_t(t), 0, 0, seed)) * total;
        std::size_t b = 0;
        double before = 0;
        while (b + 1 < blockSum.size() && before + blockSum[b] <= target) before += blockSum[b++];
        while (b > 0 && blockSum[b] == 0) --b;  // rounding pushed past the last non-zero block
        std::size_t pick = n;
        double cum = before;
        for (std::size_t i = km.blocks.begin(b); i < km.blocks.end(b); ++i) {
            if (d2[i] <= 0) continue;
            pick = i;  // the last candidate, should rounding leave cum ≤ target
            cum += d2[i];
            if (cum > target) break;
        }
        VL_CHECK_LT(pick, n);
        addCentre(pick);
        // D² update. A row whose nearest seed a has |c_t − c_a| ≥ 2|x − c_a| cannot be nearer
        // to c_t (triangle inequality) and is not read (kSeedSkipMargin absorbs rounding).
        const float* c = km.centres.data() + std::size_t(t) * km.dim;
        between.resize(std::size_t(t));
        for (int a = 0; a < t; ++a)
            between[a] = squaredDistance(c, km.centres.data() + std::size_t(a) * km.dim, km.dim);
        forEachBlock(km.blocks, progress, [&](std::size_t, std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) {
                if (between[km.label[i]] >= 4 * kSeedSkipMargin * d2[i]) continue;
                const float d = squaredDistance(km.row(i), c, km.dim);
                if (d < d2[i]) {
                    d2[i] = d;
                    km.label[i] = t;
                }
            }
        });
        if (t % 8 == 0) progress.report("CPCA k-means", 0.2 * t / clusters);
    }
}

/// argmin_c cn[c] − 2·dot[c] (lowest c on ties) and its value: kLanes running minima in one SIMD
/// register (GCC/Clang vector extensions: AVX on x86-64-v3, SSE pairs otherwise), then the lanes
/// compared in index order, then the remainder.
std::int32_t nearest(const float* cn, const float* dot, int k, float& bestOut) {
    constexpr int kLanes = 8;
    using Floats = float __attribute__((vector_size(kLanes * sizeof(float))));
    using Ints = std::int32_t __attribute__((vector_size(kLanes * sizeof(std::int32_t))));
    std::int32_t bestIndex = -1;
    float bestValue = std::numeric_limits<float>::infinity();
    int c = 0;
    if (k >= kLanes) {
        Floats best, a, d;
        std::memcpy(&a, cn, sizeof a);
        std::memcpy(&d, dot, sizeof d);
        best = a - 2 * d;
        Ints index{0, 1, 2, 3, 4, 5, 6, 7}, current = index;
        for (c = kLanes; c + kLanes <= k; c += kLanes) {
            current += kLanes;
            std::memcpy(&a, cn + c, sizeof a);
            std::memcpy(&d, dot + c, sizeof d);
            const Floats s = a - 2 * d;
            const Ints lower = s < best;  // all bits set where lower
            best = Floats((Ints(s) & lower) | (Ints(best) & ~lower));
            index = (current & lower) | (index & ~lower);
        }
        for (int l = 0; l < kLanes; ++l)
            if (bestIndex < 0 || best[l] < bestValue ||
                (best[l] == bestValue && index[l] < bestIndex)) {
                bestValue = best[l];
                bestIndex = index[l];
            }
    }
    for (; c < k; ++c) {
        const float s = cn[c] - 2 * dot[c];
        if (bestIndex < 0 || s < bestValue) {
            bestValue = s;
            bestIndex = c;
        }
    }
    bestOut = bestValue;
    return bestIndex;
}

/// Assigns every row to its nearest centre (lowest index on ties); returns how many rows changed.
std::size_t assign(KMeans& km, const core::Progress& progress) {
    const ConstRowsF centres(km.centres.data(), km.k, km.dim);
    const Eigen::VectorXf cn = centres.rowwise().squaredNorm();
    std::vector<std::size_t> changed(km.blocks.count(), 0);
    forEachBlock(km.blocks, progress, [&](std::size_t b, std::size_t begin, std::size_t end) {
        const ConstRowsF x(km.row(begin), Eigen::Index(end - begin), km.dim);
        // |x − c|² = |x|² − 2x·c + |c|²: one GEMM per block, k × rows so that the scores of a row
        // are contiguous.
        Eigen::MatrixXf dots(km.k, Eigen::Index(end - begin));
        dots.noalias() = centres * x.transpose();
        for (std::size_t i = begin; i < end; ++i) {
            float bestD;
            const std::int32_t best =
                nearest(cn.data(), dots.col(Eigen::Index(i - begin)).data(), km.k, bestD);
            if (km.label[i] != best) ++changed[b];
            km.label[i] = best;
            km.dist[i] = std::max(0.f, km.norm2[i] + bestD);
        }
    });
    std::size_t total = 0;
    for (const std::size_t c : changed) total += c;
    return total;
}

/// Rows of each cluster in row order: rows offset[c]…offset[c+1]−1 of `order`.
struct Members {
    std::vector<std::size_t> offset;
    std::vector<std::size_t> order;
    std::size_t size(int c) const { return offset[c + 1] - offset[c]; }
    std::span<const std::size_t> of(int c) const { return {order.data() + offset[c], size(c)}; }
};

Members members(const std::vector<std::int32_t>& label, int k) {
    Members m;
    m.offset.assign(std::size_t(k) + 1, 0);
    for (const std::int32_t c : label) ++m.offset[std::size_t(c) + 1];
    for (int c = 0; c < k; ++c) m.offset[c + 1] += m.offset[c];
    m.order.resize(label.size());
    std::vector<std::size_t> next(m.offset.begin(), m.offset.end() - 1);
    for (std::size_t i = 0; i < label.size(); ++i) m.order[next[label[i]]++] = i;
    return m;
}

/// Gives each empty cluster the row farthest from its centre whose cluster keeps a member.
void reseedEmpty(KMeans& km) {
    std::vector<std::size_t> count(km.k, 0);
    for (const std::int32_t c : km.label) ++count[c];
    for (int c = 0; c < km.k; ++c) {
        if (count[c] > 0) continue;
        std::size_t pick = km.blocks.rows;
        float far = 0;
        for (std::size_t i = 0; i < km.blocks.rows; ++i)
            if (km.dist[i] > far && count[km.label[i]] > 1) {
                far = km.dist[i];
                pick = i;
            }
        // Nothing to split (dist comes from |x|² − 2x·c + |c|², so recheck the farthest row
        // exactly: rows equal to their centre must not be moved): stays empty, dropped later.
        if (pick == km.blocks.rows ||
            squaredDistance(km.row(pick), km.centres.data() + std::size_t(km.label[pick]) * km.dim,
                            km.dim) == 0.f)
            continue;
        --count[km.label[pick]];
        ++count[c];
        km.label[pick] = c;
        km.dist[pick] = 0;
    }
}

/// Centres = member averages (double, row order); empty clusters keep their centre.
void updateCentres(KMeans& km, const core::Progress& progress) {
    const Members m = members(km.label, km.k);
    forEachIndex(0, km.k, [&](int c) {
        progress.checkCancel();
        if (m.size(c) == 0) return;
        Eigen::VectorXd sum = Eigen::VectorXd::Zero(km.dim);
        for (const std::size_t i : m.of(c))
            sum += Eigen::Map<const Eigen::VectorXf>(km.row(i), km.dim).cast<double>();
        Eigen::Map<Eigen::VectorXf>(km.centres.data() + std::size_t(c) * km.dim, km.dim) =
            (sum / double(m.size(c))).cast<float>();
    });
}

// ---- PCA per cluster ---------------------------------------------------------------------------

/// Orthonormal basis (n × p) of the columns of y (Householder QR, thin Q).
Eigen::MatrixXd orthonormalise(const Eigen::MatrixXd& y) {
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(y);
    return qr.householderQ() * Eigen::MatrixXd::Identity(y.rows(), y.cols());
}

/// Candidate directions (columns of v, dim × r) with their singular values, descending.
struct Directions {
    Eigen::MatrixXd v;
    Eigen::VectorXd sigma;
};

/// Top `want` directions of the centred member matrix a (n × dim), see the header for the method.
Directions principalDirections(const Eigen::MatrixXd& a, int want, std::uint64_t seed,
                               int clusterIndex) {
    const Eigen::Index n = a.rows(), dim = a.cols();
    const Eigen::Index small = std::min(n, dim);
    Directions d;
    if (small <= kExactPcaLimit) {
        const Eigen::Index r = std::min<Eigen::Index>(want, small);
        d.v.resize(dim, r);
        d.sigma.resize(r);
        if (n < dim) {
            // Gram matrix A·Aᵀ = U Λ Uᵀ; directions Aᵀu/σ.
            const Eigen::MatrixXd gram = a * a.transpose();
            const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(gram);
            for (Eigen::Index j = 0; j < r; ++j) {
                const Eigen::Index col = n - 1 - j;  // eigenvalues ascend
                d.sigma[j] = std::sqrt(std::max(0.0, es.eigenvalues()[col]));
                d.v.col(j) = a.transpose() * es.eigenvectors().col(col);
                const double len = d.v.col(j).norm();
                if (len > 0) d.v.col(j) /= len;
            }
        } else {
            // Covariance Aᵀ·A = V Λ Vᵀ.
            const Eigen::MatrixXd cov = a.transpose() * a;
            const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(cov);
            for (Eigen::Index j = 0; j < r; ++j) {
                const Eigen::Index col = dim - 1 - j;
                d.sigma[j] = std::sqrt(std::max(0.0, es.eigenvalues()[col]));
                d.v.col(j) = es.eigenvectors().col(col);
            }
        }
        return d;
    }
    // Randomized subspace iteration (Halko et al. 2011, Alg. 4.4) + Rayleigh–Ritz.
    const Eigen::Index p = std::min<Eigen::Index>(want + kOversampling, small);
    Eigen::MatrixXd omega(dim, p);
    for (Eigen::Index j = 0; j < p; ++j)
        for (Eigen::Index i = 0; i < dim; ++i)
            omega(i, j) = 2 * core::toUnitDouble(core::hashCounters(
                                  std::uint64_t(clusterIndex), std::uint64_t(j), std::uint64_t(i),
                                  seed ^ 0x7063615f72616e64ULL)) -
                          1;
    Eigen::MatrixXd q = orthonormalise(a * omega);
    for (int it = 0; it < kPowerIterations; ++it) {
        const Eigen::MatrixXd z = orthonormalise(a.transpose() * q);
        q = orthonormalise(a * z);
    }
    const Eigen::MatrixXd b = q.transpose() * a;  // p × dim
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(b, Eigen::ComputeThinV);
    const Eigen::Index r = std::min<Eigen::Index>(want, svd.singularValues().size());
    d.v = svd.matrixV().leftCols(r);
    d.sigma = svd.singularValues().head(r);
    return d;
}

/// Mean and components of one cluster into mean[dim], basis[components × dim] (zeros kept).
void clusterPca(const float* data, int dim, std::span<const std::size_t> rows, int components,
                std::uint64_t seed, int clusterIndex, float* meanOut, float* basisOut) {
    const Eigen::Index n = Eigen::Index(rows.size());
    Eigen::VectorXd mean = Eigen::VectorXd::Zero(dim);
    for (const std::size_t i : rows)
        mean += Eigen::Map<const Eigen::VectorXf>(data + i * dim, dim).cast<double>();
    mean /= double(n);
    Eigen::Map<Eigen::VectorXf>(meanOut, dim) = mean.cast<float>();
    std::fill(basisOut, basisOut + std::size_t(components) * dim, 0.f);
    if (components == 0 || n < 2) return;

    Eigen::MatrixXd a(n, dim);
    for (Eigen::Index r = 0; r < n; ++r)
        a.row(r) = Eigen::Map<const Eigen::RowVectorXf>(data + rows[r] * dim, dim).cast<double>() -
                   mean.transpose();
    const Directions d = principalDirections(a, components, seed, clusterIndex);
    if (d.sigma.size() == 0 || !(d.sigma[0] > 0)) return;  // no spread: equal rows

    // Keep the directions above the rank tolerance, re-orthonormalised (modified Gram–Schmidt in
    // order of variance) so that rounding in the Gram path cannot leave them skew; fix the sign.
    int kept = 0;
    std::vector<Eigen::VectorXd> done;
    for (Eigen::Index j = 0; j < d.sigma.size(); ++j) {
        if (!(d.sigma[j] > kRankTolerance * d.sigma[0])) break;
        Eigen::VectorXd v = d.v.col(j);
        for (const Eigen::VectorXd& u : done) v -= u.dot(v) * u;
        const double len = v.norm();
        if (!(len > 0.5)) continue;  // (numerically) in the span of the stronger ones
        v /= len;
        Eigen::Index big = 0;
        v.cwiseAbs().maxCoeff(&big);
        if (v[big] < 0) v = -v;
        done.push_back(v);
        Eigen::Map<Eigen::VectorXf>(basisOut + std::size_t(kept) * dim, dim) = v.cast<float>();
        ++kept;
    }
}

}  // namespace

void Cpca::reconstruct(std::size_t row, float* out) const {
    const int c = cluster[row];
    const float* m = mean(c);
    std::copy(m, m + dim, out);
    const float* w = weights.data() + row * std::size_t(components);
    for (int j = 0; j < components; ++j) {
        const float* b = component(c, j);
        for (int t = 0; t < dim; ++t) out[t] += w[j] * b[t];
    }
}

void Cpca::radiance(std::span<const glm::vec3> light, std::span<glm::vec3> out) const {
    radiance(light, 1, out);
}

std::vector<float> Cpca::projectLight(std::span<const glm::vec3> light, int exitance) const {
    VL_CHECK_GE(exitance, 1);
    const std::size_t n = std::size_t(exitance);
    VL_CHECK_EQ(light.size() * 3 * n, std::size_t(dim));
    const std::size_t block = light.size() * 3;  // one exitance coefficient's entries
    const std::size_t perCluster = std::size_t(components + 1) * n * 3;
    std::vector<float> projected(std::size_t(clusters) * perCluster);
    // Each entry in double, rounded to float once (Zhang eq. 18).
    auto project = [&](const float* v, float* out) {
        glm::dvec3 s(0.0);
        for (std::size_t k = 0; k < light.size(); ++k)
            for (int ch = 0; ch < 3; ++ch) s[ch] += double(v[k * 3 + ch]) * light[k][ch];
        for (int ch = 0; ch < 3; ++ch) out[ch] = float(s[ch]);
    };
    forEachIndex(0, clusters, [&](int c) {
        float* p = projected.data() + std::size_t(c) * perCluster;
        for (std::size_t j = 0; j < n; ++j) {
            project(mean(c) + j * block, p + j * 3);
            for (int i = 0; i < components; ++i)
                project(component(c, i) + j * block, p + ((1 + std::size_t(i)) * n + j) * 3);
        }
    });
    return projected;
}

void Cpca::radiance(std::span<const glm::vec3> light, int exitance,
                    std::span<glm::vec3> out) const {
    const std::size_t n = std::size_t(exitance);
    const std::vector<float> projected = projectLight(light, exitance);
    VL_CHECK_EQ(out.size(), rows() * n);
    const std::size_t perCluster = std::size_t(components + 1) * n * 3;
    auto at = [&](const float* p, std::size_t i, std::size_t j) {
        const float* v = p + (i * n + j) * 3;
        return glm::vec3(v[0], v[1], v[2]);
    };
    // Per row: the cluster's projected mean plus the weighted projected components (eq. 19).
    forEachBlock(Blocks{rows()}, core::Progress::none(),
                 [&](std::size_t, std::size_t begin, std::size_t end) {
                     for (std::size_t r = begin; r < end; ++r) {
                         const float* p = projected.data() + std::size_t(cluster[r]) * perCluster;
                         const float* w = weights.data() + r * std::size_t(components);
                         for (std::size_t j = 0; j < n; ++j) {
                             glm::vec3 s = at(p, 0, j);
                             for (int i = 0; i < components; ++i)
                                 s += w[i] * at(p, 1 + std::size_t(i), j);
                             out[r * n + j] = s;
                         }
                     }
                 });
}

std::size_t Cpca::bytes() const {
    return (means.size() + basis.size() + weights.size()) * sizeof(float) +
           cluster.size() * sizeof(std::int32_t);
}

std::ostream& operator<<(std::ostream& os, const Cpca& c) {
    return os << "Cpca{rows " << c.rows() << ", dim " << c.dim << ", clusters " << c.clusters
              << ", components " << c.components << ", " << c.iterations
              << " Lloyd iterations, relative L2 error " << c.relativeL2Error << ", " << c.bytes()
              << " bytes}";
}

Cpca compressCpca(std::span<const float> rows, int dim, const CpcaOptions& options,
                  const core::Progress& progress) {
    VL_CHECK_GE(dim, 1);
    VL_CHECK_EQ(rows.size() % std::size_t(dim), std::size_t(0));
    checkOptions(options);
    Cpca out;
    out.dim = dim;
    out.components = options.components;
    const std::size_t n = rows.size() / std::size_t(dim);
    if (n == 0) return out;

    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
    arena.execute([&] {
        checkFinite(rows, dim, progress);

        // 1. k-means.
        KMeans km;
        km.data = rows.data();
        km.dim = dim;
        km.blocks = Blocks{n};
        km.label.assign(n, -1);
        km.norm2.resize(n);
        forEachBlock(km.blocks, progress, [&](std::size_t, std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i)
                km.norm2[i] = Eigen::Map<const Eigen::VectorXf>(km.row(i), dim).squaredNorm();
        });
        seedKMeansPlusPlus(km, int(std::min<std::size_t>(n, std::size_t(options.clusters))),
                           options.seed, progress);
        progress.report("CPCA k-means", 0.2);
        assign(km, progress);
        for (int it = 0; it < options.iterations; ++it) {
            reseedEmpty(km);
            updateCentres(km, progress);
            const std::size_t changed = assign(km, progress);
            ++out.iterations;
            progress.report("CPCA k-means", 0.2 + 0.8 * (it + 1) / options.iterations);
            if (changed == 0) break;
        }
        progress.report("CPCA k-means", 1.0);

        // Drop empty clusters, keeping seed order.
        std::vector<std::int32_t> renumber(km.k, -1);
        for (const std::int32_t c : km.label) renumber[c] = 0;
        for (int c = 0; c < km.k; ++c)
            if (renumber[c] == 0) renumber[c] = out.clusters++;
        out.cluster.resize(n);
        for (std::size_t i = 0; i < n; ++i) out.cluster[i] = renumber[km.label[i]];
        km = KMeans{};

        // 2. PCA per cluster.
        const Members m = members(out.cluster, out.clusters);
        out.means.resize(std::size_t(out.clusters) * dim);
        out.basis.resize(std::size_t(out.clusters) * out.components * dim);
        for (int first = 0; first < out.clusters; first += kPcaBatch) {
            forEachIndex(first, std::min(out.clusters, first + kPcaBatch), [&](int c) {
                progress.checkCancel();
                clusterPca(rows.data(), dim, m.of(c), out.components, options.seed, c,
                           out.means.data() + std::size_t(c) * dim,
                           out.basis.data() + std::size_t(c) * out.components * dim);
            });
            progress.report("CPCA PCA",
                            0.9 * std::min(out.clusters, first + kPcaBatch) / out.clusters);
        }

        // Weights (projections on the stored components) and the reconstruction error.
        out.weights.resize(n * std::size_t(out.components));
        const Blocks blocks{n};
        std::vector<double> errorSum(blocks.count()), normSum(blocks.count());
        forEachBlock(blocks, progress, [&](std::size_t b, std::size_t begin, std::size_t end) {
            std::vector<float> rec(dim);
            double e = 0, s = 0;
            for (std::size_t i = begin; i < end; ++i) {
                const float* x = rows.data() + i * dim;
                const int c = out.cluster[i];
                const float* mu = out.mean(c);
                for (int j = 0; j < out.components; ++j) {
                    const float* v = out.component(c, j);
                    double w = 0;
                    for (int t = 0; t < dim; ++t) w += (double(x[t]) - mu[t]) * v[t];
                    out.weights[i * out.components + j] = float(w);
                }
                out.reconstruct(i, rec.data());
                for (int t = 0; t < dim; ++t) {
                    const double diff = double(x[t]) - rec[t];
                    e += diff * diff;
                    s += double(x[t]) * x[t];
                }
            }
            errorSum[b] = e;
            normSum[b] = s;
        });
        double e = 0, s = 0;
        for (std::size_t b = 0; b < blocks.count(); ++b) {
            e += errorSum[b];
            s += normSum[b];
        }
        out.relativeL2Error = s > 0 ? std::sqrt(e / s) : 0.0;
        progress.report("CPCA PCA", 1.0);
    });
    return out;
}

}  // namespace voxlight::pvrt
