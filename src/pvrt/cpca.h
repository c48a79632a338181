// SPDX-License-Identifier: MIT
#pragma once
// Clustered principal component analysis (CPCA) of PVRT transfer rows: Sloan, Hall, Hart & Snyder
// 2003, "Clustered principal components for precomputed radiance transfer" (SIGGRAPH), as used by
// Zhang, Dong & Ma 2013 §7.1 (128 clusters, N = 4 components) and rendered with their "early
// evaluation" §7.2 (radiance() below).
//
// Each row x (dim floats; for PVRT a transfer matrix, m basis lights × RGB, layout [k][channel],
// transfer.h) is approximated as
//   x ≈ rec(x) = mean_c + Σ_{j<N} w_j · b_{c,j},   c = cluster(x),  w_j = (x − mean_c)·b_{c,j}.
//
// Algorithm (compressCpca):
//  1. k-means (vector quantisation, Sloan §3's "VQ" step): k-means++ seeding (Arthur & Vassilvitskii
//     2007) drawn deterministically from options.seed, then Lloyd iterations until no row changes
//     cluster or options.iterations is reached. Assignment uses the squared Euclidean distance,
//     evaluated as |c|² − 2x·c per fixed block of rows (a float GEMM): O(rows·clusters·dim) per
//     iteration. Centres are the averages of their members, summed in double in row order.
//     - Fewer distinct rows than clusters (in particular fewer rows): seeding stops when every row
//       coincides with a seed, so there are as many clusters as distinct rows (at most).
//     - A cluster that an assignment leaves empty is re-seeded, before the next update, with the
//       row farthest from its centre (lowest row index on ties) whose cluster keeps a member.
//       Clusters empty after the last assignment (or with no row left to take) are dropped;
//       `clusters` is the number kept, ≤ options.clusters, numbered 0…clusters−1 in seed order.
//     Seeding skips the distance of a row to a new seed when the triangle inequality shows it
//     cannot be nearer than the row's current seed; worst case O(rows·clusters·dim).
//  2. PCA per cluster (n members, centred member matrix A, n × dim), keeping the top N directions:
//     - min(n, dim) ≤ kExactPcaLimit (128): exact, from the symmetric eigendecomposition (double)
//       of the Gram matrix A·Aᵀ (n × n) when n < dim, else of the covariance Aᵀ·A (dim × dim).
//       Cost O(n·dim·min(n,dim) + min(n,dim)³).
//     - otherwise (large dim *and* large clusters, e.g. DSF 162/642 × 3): randomized subspace
//       iteration (Halko, Martinsson & Tropp 2011, Alg. 4.4 + Rayleigh–Ritz) with p = N + 10
//       columns and kPowerIterations (4) power steps, QR re-orthonormalised each step; the start
//       block is a deterministic pseudo-random function of (seed, cluster). Cost
//       O(n·dim·p·(2q + 2)): the dim × dim covariance is never formed. Exact when the cluster's
//       rank ≤ p; otherwise close to the optimal truncation: the captured energy misses about
//       (σ_{p+1}/σ_N)^{2q+1} of the tail (a spectrum falling by 0.85 per direction: the error is
//       within 1e-5 of the SVD optimum, tests; without power steps it is 2e-3 off).
//     Memory: each cluster in flight holds its centred member matrix (n × dim doubles).
//     Components come in order of decreasing variance; a direction whose singular value is
//     ≤ kRankTolerance (1e-5) × the largest one (or a cluster with no spread at all, e.g. one
//     member or equal rows) is a zero row of `basis` with zero weights, so a rank-r cluster
//     has min(r, N) non-zero components. The sign of each component makes its largest-magnitude
//     entry positive. Weights are the projections of each row on its cluster's stored (float)
//     components, computed in double.
//
// Determinism: the result is a function of (rows, dim, options minus threads): every parallel loop
// works on fixed blocks of rows or on whole clusters, and every sum is taken in row order or
// combined per fixed block in block order — never in thread order.
//
// Errors: non-finite input (NaN, ±∞) → InputError (source "pvrt", field "transfer[row][entry]");
// clusters < 1, components < 0, iterations < 0 or threads < 0 → InputError (field "cpca.<name>").
// rows.size() must be a multiple of dim ≥ 1 (VL_CHECK). No rows → an empty Cpca (clusters = 0).
// Cancellable through core::Progress (CancelledError), stages "CPCA k-means" and "CPCA PCA".
#include <cstdint>
#include <glm/glm.hpp>
#include <iosfwd>
#include <span>
#include <vector>

#include "core/progress.h"

namespace voxlight::pvrt {

struct CpcaOptions {
    int clusters = 128;   ///< requested k-means clusters (≥ 1); fewer when rows are fewer
    int components = 4;   ///< N, principal directions kept per cluster (≥ 0; 0 = plain VQ)
    int iterations = 20;  ///< at most this many Lloyd iterations (≥ 0) after seeding
    std::uint64_t seed = 1;
    int threads = 0;  ///< 0 = all hardware threads; the result does not depend on it
};

/// min(n, dim) up to which a cluster's PCA is an exact eigendecomposition (Gram or covariance).
inline constexpr int kExactPcaLimit = 128;
/// Power steps of the randomized subspace iteration used above kExactPcaLimit.
inline constexpr int kPowerIterations = 4;
/// Extra columns of that iteration's block beyond N.
inline constexpr int kOversampling = 10;
/// Components whose singular value is at most this fraction of the cluster's largest are zero
/// (float input carries ~1e-7 relative noise; a genuine direction this weak adds < 1e-10 of the
/// cluster's energy).
inline constexpr double kRankTolerance = 1e-5;

struct Cpca {
    int dim = 0;                        ///< floats per row
    int clusters = 0;                   ///< clusters kept (≤ CpcaOptions::clusters)
    int components = 0;                 ///< N
    std::vector<float> means;           ///< clusters × dim
    std::vector<float> basis;           ///< clusters × components × dim, orthonormal rows or 0
    std::vector<std::int32_t> cluster;  ///< per row, in 0…clusters−1
    std::vector<float> weights;         ///< rows × components
    /// sqrt(Σ|x − rec(x)|² / Σ|x|²) over all rows (reconstruct() in float, sums in double); 0
    /// when every row is 0.
    double relativeL2Error = 0;
    /// Lloyd iterations run (fewer than CpcaOptions::iterations when no row changed cluster).
    int iterations = 0;

    std::size_t rows() const { return cluster.size(); }
    const float* mean(int c) const { return means.data() + std::size_t(c) * dim; }
    const float* component(int c, int j) const {
        return basis.data() + (std::size_t(c) * components + j) * dim;
    }
    /// rec(row) into out[0…dim).
    void reconstruct(std::size_t row, float* out) const;
    /// Radiance of every row under lights given as m = dim/3 RGB coefficients (basis.h's
    /// project()): out[row][ch] = Σ_k rec(row)[k·3 + ch] · light[k][ch] (VL_CHECK: light.size()·3
    /// = dim, out.size() = rows()). Computed the CPCA way (Zhang §7.2 eq. 18–19): per cluster
    /// project its mean and components onto the light (clusters × (N+1) × dim, in double), then
    /// per row mean·light + Σ_j w_j (b_j·light) (rows × N × 3). Runs in the caller's oneTBB arena;
    /// each output depends only on its row, so the result does not depend on threads.
    void radiance(std::span<const glm::vec3> light, std::span<glm::vec3> out) const;
    /// The same for rows of n = exitance blocks of m·3 (transfer.h's [j][k][rgb]): out[row·n + j]
    /// = Σ_k rec(row)[(j·m + k)·3 + ch] · light[k][ch] (dim = n·m·3, out.size() = rows()·n).
    void radiance(std::span<const glm::vec3> light, int exitance, std::span<glm::vec3> out) const;
    /// The lights projected onto every cluster's mean and components (Zhang eq. 18), the first
    /// half of radiance(): clusters × (N+1) × n × RGB floats, [cluster][0 = mean, 1+i = component
    /// i][j][channel], each a double sum over the m basis lights rounded to float once. radiance()
    /// and pvrt::combineCpca (radiance.h) both build on it.
    std::vector<float> projectLight(std::span<const glm::vec3> light, int exitance) const;
    /// Memory of the compressed representation.
    std::size_t bytes() const;
};

std::ostream& operator<<(std::ostream& os, const Cpca& c);

/// CPCA of `rows` (count × dim floats, row-major), see the header comment.
Cpca compressCpca(std::span<const float> rows, int dim, const CpcaOptions& options,
                  const core::Progress& progress);

}  // namespace voxlight::pvrt
