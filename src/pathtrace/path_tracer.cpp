// SPDX-License-Identifier: MIT
#include "pathtrace/path_tracer.h"

#include <tbb/blocked_range2d.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <tuple>
#include <type_traits>

#include "core/color.h"
#include "core/error.h"
#include "core/timing.h"
#include "grid/brick_traversal.h"
#include "pathtrace/brdf.h"
#include "render/shading.h"

namespace voxlight::pathtrace {

namespace {

constexpr double kInvFourPi = 0.25 / std::numbers::pi;
/// Ratio tracking plays Russian roulette below this transmittance (survivors doubled): unbiased,
/// and shadow rays through dense matter stop early.
constexpr double kRouletteTransmittance = 0.1;
/// −ln kRouletteTransmittance: the optical depth below which that is.
constexpr double kRouletteDepth = std::numbers::ln10;
static_assert(kRouletteTransmittance == 0.1, "kRouletteDepth is −ln kRouletteTransmittance");
/// Null collisions one free flight or shadow ray may take. A cell that is partly empty under a
/// huge σt (10⁶/mm at a sharp TF edge) would take σt × (empty length) of them; past the budget the
/// matter ahead is opaque at the scale of a micrometre, so the flight collides where it is and the
/// shadow ray is blocked. Counted (Stats::budgetExceeded) and reported, never silent.
constexpr int kNullCollisionBudget = 4096;
/// Samples per progressive pass (the stop criteria are checked between passes).
constexpr int kSamplesPerPass = 4;
/// Samples per pixel of the first pass under a time cap: the fewest whose spread gives each
/// pixel a variance — the error estimate, the denoiser's strength and adaptive sampling's weights
/// read it (after one sample every pixel's variance reads 0: "error 0 %", nothing denoised).
constexpr int kFirstCappedPassSamples = 2;
/// Autofocus marches the centre ray at this many voxels (of the smallest spacing) per step.
constexpr double kAutofocusStepVoxels = 0.25;
/// The guides' quadrature step (voxels of the smallest spacing) and the transmittance where it
/// stops (the rest of the ray weighs less than this). Against 0.5 and 10⁻³: half the time, and
/// the denoised torso's NRMSE moved from 0.2763 to 0.2776 (4 spp).
constexpr double kGuideStepVoxels = 1.0;
constexpr double kGuideTransmittance = 1e-2;
/// Voxels per fine-majorant cell side. On the 128³ torso under ct-bone (256², 32 spp): 1 voxel
/// 5.7·10⁶ null collisions, 2 voxels 14.4·10⁶, the 4³ skip cells alone 34.8·10⁶; 1 was the fastest.
constexpr int kFineVoxels = 1;
/// Fine majorants widen each voxel cell's value range by one table cell (a sample a float rounding
/// past the cell's face, in a steep neighbour) and by this fraction of its span and magnitude
/// (rounding of the trilinear interpolation) ...
constexpr float kFineValuePad = 1e-4f;
/// ... and scale the table's maximum by this (rounding of the table's own interpolation).
constexpr float kFineSigmaPad = 1.f + 1e-5f;
/// Fine controls (residual ratio tracking's lower bounds: the table's minimum over the same
/// widened range) are scaled by this, for the same rounding.
constexpr float kFineControlPad = 1.f - 1e-5f;
/// Records of non-uniform blocks per storage chunk (PathTracer::Impl::fineOf): large enough that
/// a chunk's allocation is rare, small enough that each thread's last, partly used one wastes
/// little (at cellSize 4: 64 KB a chunk).
constexpr std::size_t kFineRecordsPerChunk = 64;

struct HalfSpace {
    glm::dvec3 point, normal;
};

struct Counters {
    std::uint64_t real = 0, null = 0, shadow = 0, violations = 0, budget = 0, surface = 0;
};

/// Kroes' constant in P_brdf = α · (1 − exp(−25 · g_f³ · |∇s|_n)) (NOTES.md §4).
constexpr double kKroesGradientScale = 25.0;

double powerHeuristic(double a, double b) { return a * a / (a * a + b * b); }

/// ln x for x > 0 within 0.06 (the exponent and a linear mantissa): where a roulette plays needs
/// no precision (any threshold keeps the estimate unbiased), only to be cheap per collision.
inline double roughLog(double x) {
    int e = 0;
    const double m = std::frexp(x, &e);  // x = m·2^e, m ∈ [0.5, 1)
    return (double(e) + 2.0 * m - 2.0) * std::numbers::ln2;
}

}  // namespace

float henyeyGreenstein(float cosTheta, float g) {
    if (std::abs(g) < 1e-4f) return float(kInvFourPi);
    const float d = 1.f + g * g - 2.f * g * cosTheta;
    return float(kInvFourPi) * (1.f - g * g) / (d * std::sqrt(d));
}

glm::dvec3 sampleHenyeyGreenstein(const glm::dvec3& forward, float g, float u1, float u2) {
    double cosT;
    if (std::abs(g) < 1e-4f) {
        cosT = 1.0 - 2.0 * u1;
    } else {
        const double s = (1.0 - double(g) * g) / (1.0 - g + 2.0 * g * u1);
        cosT = (1.0 + double(g) * g - s * s) / (2.0 * g);
    }
    cosT = std::clamp(cosT, -1.0, 1.0);
    const double sinT = std::sqrt(std::max(0.0, 1.0 - cosT * cosT));
    const double phi = 2.0 * std::numbers::pi * u2;
    // Orthonormal basis around forward (Duff et al. 2017).
    const double sign = std::copysign(1.0, forward.z);
    const double a = -1.0 / (sign + forward.z), b = forward.x * forward.y * a;
    const glm::dvec3 t1(1.0 + sign * forward.x * forward.x * a, sign * b, -sign * forward.x);
    const glm::dvec3 t2(b, sign + forward.y * forward.y * a, -forward.y);
    return glm::normalize(sinT * std::cos(phi) * t1 + sinT * std::sin(phi) * t2 + cosT * forward);
}

/// A ray's part [t0, t1] in index space, in float: p(s) = o + s·d for s ∈ [0, length] (mm from
/// t0). Starting at t0 keeps float precision where the volume is (camera rays start far away).
struct Track {
    glm::vec3 o, d, invD;
    float length = 0.f;
};

/// Octant skip distances (PathTracer::Impl::octant) over a grid of `n` cells (x fastest), 8 per
/// cell, from nonEmpty(linear index): per octant one sweep against its directions,
/// D = 1 + the smallest D of the 7 forward neighbours (their cubes of side D − 1 and the cell
/// itself make up its cube of side D); neighbours past the grid count as empty. The sweep runs
/// over `scratch`, the grid with a border of one cell a side holding 255 (past the grid: no
/// bound), so a neighbour is a fixed offset away and needs no bounds test.
template <class NonEmpty>
void octantDistances(const glm::ivec3& n, NonEmpty&& nonEmpty, std::uint8_t* out,
                     std::vector<std::uint8_t>& scratch) {
    const std::ptrdiff_t px = n.x + 2, py = n.y + 2;
    scratch.assign(std::size_t(px * py * (n.z + 2)), 255);
    std::uint8_t* d = scratch.data();
    for (int o = 0; o < 8; ++o) {
        const glm::ivec3 sgn((o & 1) ? -1 : 1, (o & 2) ? -1 : 1, (o & 4) ? -1 : 1);
        // The 7 forward neighbours' offsets in the padded grid.
        const std::ptrdiff_t ox = sgn.x, oy = sgn.y * px, oz = sgn.z * px * py;
        const std::ptrdiff_t nb[7] = {ox, oy, ox + oy, oz, ox + oz, oy + oz, ox + oy + oz};
        // Forward neighbours first: each axis swept against its direction.
        for (int mz = 0; mz < n.z; ++mz) {
            const int z = sgn.z > 0 ? n.z - 1 - mz : mz;
            for (int my = 0; my < n.y; ++my) {
                const int y = sgn.y > 0 ? n.y - 1 - my : my;
                const std::size_t row =
                    std::size_t(n.x) * (std::size_t(y) + std::size_t(n.y) * std::size_t(z));
                std::uint8_t* drow = d + 1 + px * ((y + 1) + py * (z + 1));
                for (int mx = 0; mx < n.x; ++mx) {
                    const int x = sgn.x > 0 ? n.x - 1 - mx : mx;
                    const std::size_t i = row + std::size_t(x);
                    std::uint8_t* c = drow + x;
                    std::uint8_t v = 0;
                    if (!nonEmpty(i)) {
                        std::uint8_t m = c[nb[0]];
                        for (int e = 1; e < 7; ++e) m = std::min(m, c[nb[e]]);
                        v = std::uint8_t(std::min(255, int(m) + 1));
                    }
                    *c = v;
                    out[i * 8 + std::size_t(o)] = v;
                }
            }
        }
    }
}

/// An exponential step of unit rate: −ln(1 − ξ) from a 53-bit ξ (no truncated tail in float).
float exponentialStep(core::CounterRng& rng) { return float(-std::log(1.0 - rng.uniformDouble())); }

struct PathTracer::Impl {
    std::shared_ptr<const core::Volume> volume;
    std::shared_ptr<const optics::TfTable> table;
    std::shared_ptr<const grid::BrickMajorants> cells;
    glm::dmat3 toIndex;      ///< world direction → index units (Dᵀ / spacing)
    glm::dmat3 gradToWorld;  ///< index-space gradient → world gradient (toIndexᵀ)
    Scattering scattering = Scattering::Phase;
    /// Hybrid: the opacity step h (smallest spacing, mm), h / (value range) for |∇s|_n, and
    /// 25 g_f³.
    double opacityStepMm = 1.0, gradientNorm = 0.0, gradientRate = 0.0;
    glm::dvec3 origin;
    glm::dvec3 boxLo, boxHi;  ///< volume box in index space (voxel centres; ±0.5 on a 1-voxel axis)
    std::vector<HalfSpace> keep;       ///< every plane and box face: where paths collide
    std::vector<HalfSpace> lightKeep;  ///< those with shadowsFromRemoved false: what occludes
    float globalMajorant = 0.f;
    bool majorantGrid = true;
    int cellSize = 1;
    glm::ivec3 counts{1};
    glm::ivec3 dims{1};
    /// Fine majorants: per fine cell (fineSize³ voxel cells) of every non-empty skip cell, the
    /// largest σt the table gives over the value range of its voxels (trilinear values stay
    /// within the range of the corners). fineSlot: per skip cell its block or −1 when empty.
    /// A block whose fine majorants are all equal (uniform: the block's one majorant is as
    /// tight as its cells') keeps only that value, in blockMajorant, and no per-cell data; the
    /// others keep theirs at fineOf[block]: (cellSize / fineSize)³ pairs (x fastest) of majorant
    /// and control — the smallest σt over the same widened range, a lower bound of every sample in
    /// the cell (residual ratio tracking, ratioTracking) — then their octant skip distances (8
    /// bytes each; see fineOctants). A uniform block's control is its cells' smallest
    /// (blockControl). Records are written into
    /// chunks of kFineRecordsPerChunk per thread as the blocks are built: nothing is held for
    /// the uniform ones, even while building.
    int fineSize = 1, fineCells = 1;
    std::vector<std::int32_t> fineSlot;
    std::vector<glm::ivec3> fineFirst, fineLast;       ///< per block: its fine cells (inclusive)
    std::vector<const float*> fineOf;                  ///< per block: its record, null when uniform
    std::vector<float> blockMajorant;                  ///< per block: its majorant when uniform
    std::vector<float> blockControl;                   ///< per block: its control when uniform
    std::vector<std::unique_ptr<float[]>> fineChunks;  ///< the storage fineOf points into
    std::size_t fineChunkFloats = 0;
    /// Per block, a copy of the voxels its cells read (cellSize + 1 a side, x fastest; clamped
    /// at the volume's far faces), at the volume's own type (the view converts them to float
    /// as it converts the volume's): a tracking sample in the block reads 4 rows of one small
    /// array instead of 4 rows spread over the volume (fewer cache lines). One vector per voxel
    /// type, the volume's filled. blockSampling: on (every axis ≥ 2 voxels).
    std::tuple<std::vector<std::uint8_t>, std::vector<std::int16_t>, std::vector<std::uint16_t>,
               std::vector<float>>
        corners;
    int cornerSide = 1;
    bool blockSampling = false;
    /// Octant skip distances, 8 per skip cell (octant o: bit a set for a negative direction on
    /// axis a): 0 for a non-empty cell, else the side D of the largest cube of empty cells that
    /// starts at the cell and extends D − 1 cells along the octant's directions (cells past the
    /// grid count as empty: a ray never enters them), capped at 255. A ray heading into the
    /// octant stays in that cube until its D-th boundary crossing on some axis, so it jumps
    /// there: unlike the symmetric skip distances, matter behind the ray does not shorten the
    /// jump (most empty cells next to bone have a symmetric distance of 1 or 2).
    std::vector<std::uint8_t> octant;
    /// The same per fine cell of each non-uniform block (in its record, after the (majorant,
    /// control) pairs), over
    /// the fine majorants, cells past the block counting as empty (a piece ends where the ray
    /// leaves its block).
    static const std::uint8_t* fineOctants(const float* record, std::size_t entries) {
        return reinterpret_cast<const std::uint8_t*>(record + 2 * entries);
    }
    /// Index-space box of the non-empty skip cells (empty when lo > hi).
    glm::vec3 busyLo{1.f}, busyHi{0.f};

    glm::dvec3 indexOf(const glm::dvec3& world) const { return toIndex * (world - origin); }

    template <class View>
    float sigma(const View& v, const glm::dvec3& ijk) const {
        return table->extinction(v.sample(float(ijk.x), float(ijk.y), float(ijk.z)));
    }
    template <class View>
    float sigma(const View& v, const glm::vec3& ijk) const {
        return table->extinction(v.sample(ijk.x, ijk.y, ijk.z));
    }

    /// The value at index point p, as v.sample(p) bit for bit: the trilinear sample reads block
    /// `blk`'s corner copy when the cell VolumeView::sample picks (after its clamps) lies in the
    /// block, else the volume; the same arithmetic on the same floats.
    template <class View>
    [[gnu::always_inline]] float valueAt(const View& v, int blk, const glm::vec3& p) const {
        if (blk < 0) return v.sample(p.x, p.y, p.z);
        const float x = std::min(std::max(p.x, 0.f), float(v.nx - 1));
        const float y = std::min(std::max(p.y, 0.f), float(v.ny - 1));
        const float z = std::min(std::max(p.z, 0.f), float(v.nz - 1));
        const int i = std::min(int(x), v.nx - 2), j = std::min(int(y), v.ny - 2),
                  kk = std::min(int(z), v.nz - 2);
        const glm::ivec3 o = fineFirst[std::size_t(blk)] * fineSize;
        const unsigned li = unsigned(i - o.x), lj = unsigned(j - o.y), lk = unsigned(kk - o.z);
        const unsigned last = unsigned(cornerSide - 2);
        if ((li > last) | (lj > last) | (lk > last)) return v.sample(p.x, p.y, p.z);
        const float fx = x - float(i), fy = y - float(j), fz = z - float(kk);
        const std::size_t dj = std::size_t(cornerSide), dk = dj * dj;
        using T = std::remove_cvref_t<decltype(*v.data)>;
        const T* q = std::get<std::vector<T>>(corners).data() + std::size_t(blk) * dk * dj + li +
                     dj * lj + dk * lk;
        // The view's arithmetic on the same converted values (VolumeView::sample).
        const float c00 = float(q[0]) + fx * (float(q[1]) - float(q[0]));
        const float c10 = float(q[dj]) + fx * (float(q[dj + 1]) - float(q[dj]));
        const float c01 = float(q[dk]) + fx * (float(q[dk + 1]) - float(q[dk]));
        const float c11 = float(q[dk + dj]) + fx * (float(q[dk + dj + 1]) - float(q[dk + dj]));
        const float c0 = c00 + fy * (c10 - c00);
        const float c1 = c01 + fy * (c11 - c01);
        return v.slope * (c0 + fz * (c1 - c0)) + v.intercept;
    }

    /// ∇s (value/mm, world) at index point ijk by central differences one voxel apart.
    template <class View>
    glm::dvec3 gradient(const View& v, const glm::dvec3& ijk) const {
        const float x = float(ijk.x), y = float(ijk.y), z = float(ijk.z);
        const glm::dvec3 gi(0.5 * (double(v.sample(x + 1.f, y, z)) - v.sample(x - 1.f, y, z)),
                            0.5 * (double(v.sample(x, y + 1.f, z)) - v.sample(x, y - 1.f, z)),
                            0.5 * (double(v.sample(x, y, z + 1.f)) - v.sample(x, y, z - 1.f)));
        return gradToWorld * gi;
    }

    /// P_brdf (header comment) for σt and the gradient's length; 0 without a normal.
    double brdfProbability(double sigma, double gradLen) const {
        if (scattering == Scattering::Phase || !(gradLen > 0.0) || !std::isfinite(gradLen))
            return 0.0;
        if (scattering == Scattering::Brdf) return 1.0;
        const double opacity = -std::expm1(-sigma * opacityStepMm);
        return opacity * -std::expm1(-gradientRate * gradLen * gradientNorm);
    }

    Track track(const Ray& ray, double t0, double t1) const {
        Track k;
        k.o = glm::vec3(indexOf(ray.origin + t0 * ray.direction));
        k.d = glm::vec3(toIndex * ray.direction);
        // On a one-voxel axis every sample clamps to index 0 and the grids have one cell: the
        // track runs at index 0 there, so no DDA sees a cell face at 0 inside the slab ±0.5.
        for (int a = 0; a < 3; ++a)
            if (dims[a] == 1) k.o[a] = 0.f, k.d[a] = 0.f;
        for (int a = 0; a < 3; ++a) k.invD[a] = k.d[a] != 0.f ? 1.f / k.d[a] : 0.f;
        k.length = float(t1 - t0);
        return k;
    }

    /// Fills `octant` from the skip cells' majorants.
    void buildOctants() {
        octant.assign(cells->size() * 8, 0);
        std::vector<std::uint8_t> scratch;
        octantDistances(
            counts, [&](std::size_t i) { return cells->majorant(i) > 0.f; }, octant.data(),
            scratch);
    }

    /// Fills the fine majorants of every non-empty skip cell.
    void buildFine() {
        const int fs = fineSize, fc = fineCells;
        const std::size_t block = std::size_t(fc) * fc * fc;
        fineSlot.assign(cells->size(), -1);
        for (int z = 0; z < counts.z; ++z)
            for (int y = 0; y < counts.y; ++y)
                for (int x = 0; x < counts.x; ++x) {
                    const std::size_t i = cells->index(x, y, z);
                    if (!(cells->majorant(i) > 0.f)) continue;
                    fineSlot[i] = std::int32_t(fineFirst.size());
                    const glm::ivec3 first = glm::ivec3(x, y, z) * fc;
                    fineFirst.push_back(first);
                    fineLast.push_back(glm::min(first + fc, (dims + fs - 1) / fs) - 1);
                }
        const std::size_t blocks = fineFirst.size();
        fineOf.assign(blocks, nullptr);
        blockMajorant.assign(blocks, 0.f);
        blockControl.assign(blocks, 0.f);
        // A record: the majorants, the controls, then 8 bytes of octant distances per entry (2
        // floats' room).
        const std::size_t record = 4 * block;
        fineChunkFloats = record * kFineRecordsPerChunk;
        struct Chunks {
            std::vector<std::unique_ptr<float[]>> chunks;
            std::size_t used = 0;
            std::vector<float> scratch, lo, hi;
            std::vector<std::uint8_t> octants;  ///< octantDistances' scratch
        };
        tbb::enumerable_thread_specific<Chunks> perThread;
        blockSampling = dims.x >= 2 && dims.y >= 2 && dims.z >= 2;
        cornerSide = cellSize + 1;
        const std::size_t side = std::size_t(cornerSide), cube = side * side * side;
        const float widen = table->cellWidth();
        const float anyValue = table->maxExtinction(std::numeric_limits<float>::lowest(),
                                                    std::numeric_limits<float>::max()) *
                               kFineSigmaPad;
        volume->visit([&](const auto& v) {
            using T = std::remove_cvref_t<decltype(*v.data)>;
            auto& corner = std::get<std::vector<T>>(corners);
            if (blockSampling) corner.assign(blocks * cube, T(0));
            tbb::parallel_for(std::size_t(0), blocks, [&](std::size_t b) {
                const glm::ivec3 first = fineFirst[b], last = fineLast[b];
                const float coarse =
                    cells->majorant(cells->index(first.x / fc, first.y / fc, first.z / fc));
                Chunks& own = perThread.local();
                own.scratch.resize(2 * block);
                float* out = own.scratch.data();
                float* control = out + block;
                // The block's voxels, cellSize + 1 a side from its first voxel, clamped at the
                // volume's far faces (where VolumeView::sample clamps too), into the corner copy
                // (when the tracker reads one) and, as the view's values (slope · stored +
                // intercept: what its trilinear sample returns at a voxel), into lo/hi — a
                // non-finite one as an infinite range.
                T* c = blockSampling ? corner.data() + b * cube : nullptr;
                own.lo.resize(cube);
                own.hi.resize(cube);
                float* lo = own.lo.data();
                float* hi = own.hi.data();
                const glm::ivec3 o = first * fs;
                for (std::size_t z = 0; z < side; ++z)
                    for (std::size_t y = 0; y < side; ++y) {
                        const glm::ivec3 row =
                            glm::min(o + glm::ivec3(0, int(y), int(z)), dims - 1);
                        const T* src =
                            v.data + v.sy * std::size_t(row.y) + v.sz * std::size_t(row.z);
                        const std::size_t e0 = side * (y + side * z);
                        for (std::size_t x = 0; x < side; ++x) {
                            const T stored = src[std::min(o.x + int(x), dims.x - 1)];
                            if (c) c[e0 + x] = stored;
                            const float val = v.slope * float(stored) + v.intercept;
                            const bool ok = std::isfinite(val);
                            lo[e0 + x] = ok ? val : -INFINITY;
                            hi[e0 + x] = ok ? val : INFINITY;
                        }
                    }
                // Each fine cell's value range over its (fs + 1)³ voxels, axis by axis: a
                // window of fs + 1 values every fs along x, then y, then z.
                // Axis a reduces n[a] = side values to fc windows in place (the window's first
                // value's slot); strides as laid out: x fastest with stride 1, y side, z side².
                const std::size_t stride[3] = {1, side, side * side};
                std::size_t n[3] = {side, side, side};
                for (int a = 0; a < 3; ++a) {
                    const int b1 = (a + 1) % 3, b2 = (a + 2) % 3;
                    for (std::size_t u = 0; u < n[b1]; ++u)
                        for (std::size_t w = 0; w < n[b2]; ++w) {
                            const std::size_t base = u * stride[b1] + w * stride[b2];
                            for (int f = 0; f < fc; ++f) {
                                const std::size_t at = base + std::size_t(f * fs) * stride[a];
                                float l = lo[at], h = hi[at];
                                for (int t = 1; t <= fs; ++t) {
                                    l = std::min(l, lo[at + std::size_t(t) * stride[a]]);
                                    h = std::max(h, hi[at + std::size_t(t) * stride[a]]);
                                }
                                // Slot f·stride[a] keeps window f (≥ its own start: the
                                // windows are read before they are overwritten).
                                lo[base + std::size_t(f) * stride[a]] = l;
                                hi[base + std::size_t(f) * stride[a]] = h;
                            }
                        }
                    n[a] = std::size_t(fc);
                }
                for (std::size_t e = 0; e < block; ++e) {  // cells past the grid
                    out[e] = coarse;
                    control[e] = 0.f;
                }
                float leastControl = INFINITY;
                for (int k = first.z; k <= last.z; ++k)
                    for (int j = first.y; j <= last.y; ++j)
                        for (int i = first.x; i <= last.x; ++i) {
                            // Fine cell (i, j, k): its range at its first voxel's slot of the
                            // copy, its majorant in `out` (fc a side).
                            const std::size_t li = std::size_t(i - first.x),
                                              lj = std::size_t(j - first.y),
                                              lk = std::size_t(k - first.z);
                            const std::size_t at = li + side * (lj + side * lk);
                            const std::size_t e =
                                li + std::size_t(fc) * (lj + std::size_t(fc) * lk);
                            float& m = out[e];
                            const float l = lo[at], h = hi[at];
                            // A non-finite voxel: a sample in the cell may be anything the
                            // table gives (NaN reads its low end, ±∞ an end or NaN), and the
                            // skip cell's majorant ignored that voxel — the table's maximum.
                            if (!(std::isfinite(l) && std::isfinite(h))) {
                                m = anyValue;
                                leastControl = 0.f;  // its control stays 0
                                continue;
                            }
                            // Widened against float rounding of positions and interpolation.
                            const float pad = widen + kFineValuePad * (h - l) +
                                              kFineValuePad * std::max(std::abs(l), std::abs(h));
                            // Never above the skip cell's own majorant (also a bound).
                            const auto [least, most] = table->extinctionRange(l - pad, h + pad);
                            m = std::min(coarse, most * kFineSigmaPad);
                            // (A NaN minimum, which a validated table cannot give, would
                            // fall back to 0 rather than to m.)
                            const float cl = least * kFineControlPad;
                            control[e] = cl >= 0.f ? std::min(m, cl) : 0.f;
                            leastControl = std::min(leastControl, control[e]);
                        }
                blockMajorant[b] = out[0];
                // A uniform block's control: its cells' smallest (cells past the grid, which
                // no piece reaches, do not count).
                blockControl[b] = std::isfinite(leastControl) ? leastControl : 0.f;
                if (std::all_of(out, out + block, [&](float m) { return m == out[0]; })) return;
                // Not uniform: a record in this thread's chunk.
                if (own.chunks.empty() || own.used + record > fineChunkFloats) {
                    own.chunks.emplace_back(new float[fineChunkFloats]);
                    own.used = 0;
                }
                float* r = own.chunks.back().get() + own.used;
                own.used += record;
                for (std::size_t e = 0; e < block; ++e) {  // (majorant, control) pairs
                    r[2 * e] = out[e];
                    r[2 * e + 1] = control[e];
                }
                auto* distances = reinterpret_cast<std::uint8_t*>(r + 2 * block);
                // Without an empty fine cell every distance is 0 (bone, mostly: no sweeps).
                if (std::all_of(out, out + block, [](float m) { return m > 0.f; }))
                    std::fill_n(distances, 8 * block, std::uint8_t(0));
                else
                    octantDistances(
                        glm::ivec3(fc), [&](std::size_t e) { return r[2 * e] > 0.f; }, distances,
                        own.octants);
                fineOf[b] = r;
            });
        });
        for (Chunks& c : perThread)
            for (auto& chunk : c.chunks) fineChunks.push_back(std::move(chunk));
    }

    /// Calls f(sa, sb, majorant, control, block) for consecutive pieces of the track with a
    /// constant majorant (and a lower bound of σt there, the control; 0 where none is kept)
    /// until f returns false (block: the fine block whose corner copy valueAt may read,
    /// or −1): the skip cells by a DDA (Amanatides & Woo), empty ones crossed in
    /// jumps (their skip distances), non-empty ones in voxel cells with the fine majorants. Under
    /// one global majorant: one piece.
    template <class F>
    void traverse(const Track& k, F&& f) const {
        if (!(k.length > 0.f)) return;
        if (!majorantGrid) {
            f(0.f, k.length, globalMajorant, 0.f, -1);
            return;
        }
        // Only the part inside the box of the non-empty skip cells (outside it every cell is
        // empty; widened a little against rounding, which costs nothing there).
        float s0 = 0.f, s1 = k.length;
        for (int a = 0; a < 3; ++a) {
            if (k.d[a] == 0.f) {
                if (k.o[a] < busyLo[a] || k.o[a] > busyHi[a]) return;
                continue;
            }
            float ta = (busyLo[a] - k.o[a]) * k.invD[a], tb = (busyHi[a] - k.o[a]) * k.invD[a];
            if (ta > tb) std::swap(ta, tb);
            s0 = std::max(s0, ta);
            s1 = std::min(s1, tb);
        }
        if (!(s1 > s0)) return;
        grid::CellDda dda(*cells, k.o, k.d, s0, s1);
        const std::uint8_t* oct =
            octant.data() + ((k.d.x < 0.f) | ((k.d.y < 0.f) << 1) | ((k.d.z < 0.f) << 2));
        float sa, sb;
        std::size_t i;
        while (!dda.done) {
            // The current (not yet returned) cell: an empty one starts an empty cube of side D
            // along the ray's octant, which the ray leaves at its D-th crossing on some axis; the
            // jump makes the cube's last cell along the ray the current one (CellDda::jump with
            // radius D − 1 uses only the cube's forward half).
            const int d = oct[dda.index * 8];
            if (d >= 2) dda.jump(d - 1);
            if (!dda.step(sa, sb, i)) return;
            if (d == 0 && !voxelCells(k, sa, sb, i, f)) return;
        }
    }

    /// The piece [sa, sb] of the track inside non-empty skip cell `cell`, by a DDA over its fine
    /// cells; false when f stopped.
    template <class F>
    [[gnu::always_inline]] bool voxelCells(const Track& k, float sa, float sb, std::size_t cell,
                                           F&& f) const {
        const std::int32_t slot = fineSlot[cell];
        const float coarse = cells->majorant(cell);
        if (slot < 0) return f(sa, sb, coarse, 0.f, -1);
        const std::size_t b = std::size_t(slot);
        const int blk = blockSampling ? slot : -1;
        const float* m = fineOf[b];
        if (!m) return f(sa, sb, blockMajorant[b], blockControl[b], blk);
        const std::size_t entries = std::size_t(fineCells * fineCells * fineCells);
        const glm::ivec3 first = fineFirst[b], last = fineLast[b];
        const float fs = float(fineSize), invFs = 1.f / fs;
        const glm::vec3 p = k.o + sa * k.d;
        const int stride[3] = {1, fineCells, fineCells * fineCells};
        // left: steps on the axis before the DDA leaves the block (float rounding).
        int left[3], step[3];
        float tNext[3], tDelta[3], invDelta[3];
        int at = 0;
        for (int a = 0; a < 3; ++a) {
            const int v = std::clamp(int(std::floor(p[a] * invFs)), first[a], last[a]);
            at += (v - first[a]) * stride[a];
            if (k.d[a] > 0.f) {
                step[a] = stride[a];
                left[a] = last[a] - v;
                tNext[a] = (float(v + 1) * fs - k.o[a]) * k.invD[a];
                tDelta[a] = fs * k.invD[a];
                invDelta[a] = k.d[a] * invFs;
            } else if (k.d[a] < 0.f) {
                step[a] = -stride[a];
                left[a] = v - first[a];
                tNext[a] = (float(v) * fs - k.o[a]) * k.invD[a];
                tDelta[a] = -fs * k.invD[a];
                invDelta[a] = -k.d[a] * invFs;
            } else {
                step[a] = 0;
                left[a] = 0;
                tNext[a] = INFINITY;
                tDelta[a] = INFINITY;
                invDelta[a] = 0.f;
            }
        }
        const std::uint8_t* oct =
            fineOctants(m, entries) + ((k.d.x < 0.f) | ((k.d.y < 0.f) << 1) | ((k.d.z < 0.f) << 2));
        float s = sa;
        while (true) {
            const int a = tNext[0] <= tNext[1] ? (tNext[0] <= tNext[2] ? 0 : 2)
                                               : (tNext[1] <= tNext[2] ? 1 : 2);
            const float e = std::min(tNext[a], sb);
            // A piece of majorant 0 has no collision: no call (every caller skips it).
            const float mj = m[2 * std::size_t(at)];
            if (!(mj > 0.f)) {
                // An empty fine cell starts an empty cube of side d along the ray's octant: the
                // ray stays in it until its d-th crossing on some axis (tExit). Past sb: nothing
                // more in this block; else the cube's last cell along the ray becomes the current
                // one (at most d − 1 crossings per axis, as CellDda::jump).
                const int d = oct[std::size_t(at) * 8];
                if (d >= 2) {
                    const float r = float(d - 1);
                    const float tExit =
                        std::min({tNext[0] + r * tDelta[0], tNext[1] + r * tDelta[1],
                                  tNext[2] + r * tDelta[2]});
                    if (!(tExit < sb)) return true;
                    bool moved = false;
                    for (int c = 0; c < 3; ++c) {
                        if (!(tNext[c] < tExit)) continue;
                        const int j = std::min(
                            {int(std::ceil((tExit - tNext[c]) * invDelta[c])), d - 1, left[c]});
                        if (j <= 0) continue;
                        left[c] -= j;
                        at += step[c] * j;
                        tNext[c] += float(j) * tDelta[c];
                        moved = true;
                    }
                    if (moved) continue;  // else (at the block's face) one ordinary step
                }
            }
            if (e > s) {
                if (mj > 0.f && !f(s, e, mj, m[2 * std::size_t(at) + 1], blk)) return false;
                s = e;
            }
            if (!(tNext[a] < sb)) return true;
            // Float rounding left the cell before sb: the rest under the skip cell's majorant.
            if (--left[a] < 0) return !(sb > s) || f(s, sb, coarse, 0.f, blk);
            at += step[a];
            tNext[a] += tDelta[a];
        }
    }

    /// The tentative collisions along a track: one exponential optical depth ("budget") is spent
    /// across the pieces, each piece taking rate × length, so a piece without a collision costs
    /// no logarithm; at each collision a fresh one is drawn (memoryless). The rate is the
    /// piece's majorant m, or with kResidual its residual m − c over the control c (residual
    /// ratio tracking). collide(s, sa, σt, m, c, value) at each collision (sa: the piece's
    /// start), pieceEnd(sa, sb, c) after each piece with m > 0; either returning false stops the
    /// walk.
    template <bool kResidual, class View, class Collide, class PieceEnd>
    void tentativeCollisions(const View& v, const Track& k, core::CounterRng& rng, Counters& n,
                             Collide&& collide, PieceEnd&& pieceEnd) const {
        float tau = exponentialStep(rng);
        traverse(
            k, [&](float sa, float sb, float m, float c, int blk) __attribute__((always_inline)) {
                if (!(m > 0.f)) return true;
                const float r = kResidual ? m - c : m;
                if (r > 0.f) {
                    float s = sa;
                    while (true) {
                        const float room = (sb - s) * r;
                        if (tau >= room) {
                            tau -= room;
                            break;
                        }
                        s = std::min(s + tau / r, sb);
                        // The next budget now (memoryless): its logarithm overlaps the lookup's
                        // memory reads.
                        tau = exponentialStep(rng);
                        const float value = valueAt(v, blk, k.o + s * k.d);
                        const float sig = table->extinction(value);
                        // Only σt > m biases (delta tracking's acceptance and ratio tracking's
                        // weight clamp there); a σt below the control would weigh > 1 in ratio
                        // tracking — unbiased still, only noisier (tests keep it ≥ c).
                        if (sig > m) ++n.violations;
                        if (!collide(s, sa, sig, m, c, value)) return false;
                    }
                }
                return pieceEnd(sa, sb, c);
            });
    }

    /// Delta tracking over the tentative collisions: real with probability σt / majorant. With
    /// `valueOut`, the value there (what a real collision reads the TF at: the sample the
    /// acceptance test took, not a second one at the collision's position in double).
    template <class View>
    std::optional<double> freeFlight(const View& v, const Ray& ray, double t0, double t1,
                                     core::CounterRng& rng, Counters& n,
                                     float* valueOut = nullptr) const {
        std::optional<double> hit;
        int nulls = 0;
        tentativeCollisions<false>(
            v, track(ray, t0, t1), rng, n,
            [&](float s, float, float sig, float m, float, float value) {
                if (rng.uniform() * m < sig || ++nulls > kNullCollisionBudget) {
                    if (nulls > kNullCollisionBudget) ++n.budget;
                    hit = t0 + double(s);
                    if (valueOut) *valueOut = value;
                    ++n.real;
                    return false;
                }
                ++n.null;
                return true;
            },
            [](float, float, float) { return true; });
        return hit;
    }

    /// Residual ratio tracking (Novák et al. 2014) over the pieces: per piece of majorant m and
    /// control c ≤ σt ≤ m, the control's transmittance e^{−c·Δ} in closed form (summed as an
    /// optical depth) and tentative collisions at the residual rate m − c, each weighing
    /// 1 − (σt − c)/(m − c) ∈ [0, 1]: unbiased for e^{−∫σt} (for any c < m, given σt ≤ m; c ≤ σt
    /// keeps the weights ≤ 1), with fewer lookups and less variance than plain ratio tracking
    /// (c = 0) wherever σt stays near its cell's minimum (uniform tissue). Stops when the
    /// estimate reaches 0 and plays Russian roulette (survivors doubled)
    /// whenever the estimate T·e^{−τc} is below kRouletteTransmittance — at collisions and at the
    /// ends of pieces, where only τc grows.
    template <class View>
    double ratioTracking(const View& v, const Ray& ray, double t0, double t1, core::CounterRng& rng,
                         Counters& n) const {
        double T = 1.0, tauC = 0.0;
        // The roulette plays once T·e^{−τc} < kRouletteTransmittance, i.e. τc > limit =
        // ln T + kRouletteDepth: while τc = 0 that is T < kRouletteTransmittance (no logarithm),
        // after that `limit` is brought up to date (roughly: any threshold is unbiased) when T
        // changed.
        double limit = kRouletteDepth;
        bool stale = false;
        ++n.shadow;
        int steps = 0;
        bool killed = false;
        // Roulette for an estimate with control depth `depth` so far: false when it ends the ray.
        auto roulette = [&](double depth) __attribute__((always_inline)) {
            if (depth == 0.0) {
                while (T < kRouletteTransmittance) {
                    if (rng.uniform() < 0.5f) return false;
                    T *= 2.0;
                }
                stale = true;
                return true;
            }
            if (stale) {
                limit = roughLog(T) + kRouletteDepth;
                stale = false;
            }
            while (depth > limit) {
                if (rng.uniform() < 0.5f) return false;
                T *= 2.0;
                limit += std::numbers::ln2;
            }
            return true;
        };
        tentativeCollisions<true>(
            v, track(ray, t0, t1), rng, n,
            [&](float s, float sa, float sig, float m, float c, float) {
                if (++steps > kNullCollisionBudget) {
                    ++n.budget;
                    killed = true;
                    return false;
                }
                T *= std::max(0.0, 1.0 - (double(sig) - double(c)) / (double(m) - double(c)));
                stale = true;
                // The roulette with τc up to the collision.
                if (!(T > 0.0) || !roulette(tauC + double(c) * double(s - sa))) {
                    killed = true;
                    return false;
                }
                return true;
            },
            [&](float sa, float sb, float c) {
                if (!(c > 0.f)) return true;
                tauC += double(c) * double(sb - sa);
                if (roulette(tauC)) return true;
                killed = true;
                return false;
            });
        return killed ? 0.0 : T * std::exp(-tauC);
    }

    bool keptInterval(const Ray& ray, double& t0, double& t1) const {
        return cut(keep, ray, t0, t1);
    }
    bool lightInterval(const Ray& ray, double& t0, double& t1) const {
        return cut(lightKeep, ray, t0, t1);
    }

    /// Narrows [t0, t1] to the volume box and the half-spaces `halfSpaces`.
    bool cut(const std::vector<HalfSpace>& halfSpaces, const Ray& ray, double& t0,
             double& t1) const {
        const glm::dvec3 o = indexOf(ray.origin), d = toIndex * ray.direction;
        for (int a = 0; a < 3; ++a) {
            if (std::abs(d[a]) < 1e-15) {
                if (o[a] < boxLo[a] || o[a] > boxHi[a]) return false;
                continue;
            }
            double ta = (boxLo[a] - o[a]) / d[a], tb = (boxHi[a] - o[a]) / d[a];
            if (ta > tb) std::swap(ta, tb);
            t0 = std::max(t0, ta);
            t1 = std::min(t1, tb);
        }
        for (const HalfSpace& h : halfSpaces) {
            const double dn = glm::dot(ray.direction, h.normal);
            const double s = glm::dot(ray.origin - h.point, h.normal);  // ≥ 0 kept
            if (std::abs(dn) < 1e-15) {
                if (s < 0.0) return false;
                continue;
            }
            const double t = -s / dn;
            if (dn > 0.0)
                t0 = std::max(t0, t);
            else
                t1 = std::min(t1, t);
        }
        return t1 > t0;
    }
};

PathTracer::PathTracer(std::shared_ptr<const core::Volume> volume,
                       std::shared_ptr<const optics::TfTable> table,
                       std::shared_ptr<const grid::BrickMajorants> cells, Options options)
    : options_(std::move(options)) {
    if (options_.samplesPerPixel < 1) throw InputError("pathtrace", "spp", "must be at least 1");
    if (options_.maxBounces < 1) throw InputError("pathtrace", "max_bounces", "must be at least 1");
    if (!(std::abs(options_.phaseG) < 1.f))
        throw InputError("pathtrace", "phase_g", "must lie strictly between -1 and 1");
    if (!(options_.gradientFactor >= 0.f && options_.gradientFactor <= 1.f))
        throw InputError("pathtrace", "gradient_factor", "must lie in [0, 1]");
    VL_CHECK(volume && table && cells);
    auto impl = std::make_shared<Impl>();
    const core::Geometry& g = volume->geometry();
    VL_CHECK(cells->counts() ==
             (g.dims + cells->cellSize() - 1) / cells->cellSize());  // built for this volume
    impl->volume = std::move(volume);
    impl->table = std::move(table);
    impl->cells = std::move(cells);
    impl->origin = g.origin;
    const glm::dmat3 dt = glm::transpose(g.direction);
    impl->toIndex = glm::dmat3(1.0);
    for (int col = 0; col < 3; ++col)
        for (int row = 0; row < 3; ++row) impl->toIndex[col][row] = dt[col][row] / g.spacing[row];
    impl->gradToWorld = glm::transpose(impl->toIndex);
    impl->scattering = options_.scattering;
    impl->opacityStepMm = std::min({g.spacing.x, g.spacing.y, g.spacing.z});
    {
        // The volume's value range from the cells' ranges (|∇s|_n's normaliser).
        float lo = INFINITY, hi = -INFINITY;
        for (std::size_t i = 0; i < impl->cells->size(); ++i) {
            const auto& r = impl->cells->valueRange(i);
            if (std::isfinite(r[0]) && std::isfinite(r[1]) && r[0] <= r[1])
                lo = std::min(lo, r[0]), hi = std::max(hi, r[1]);
        }
        impl->gradientNorm = hi > lo ? impl->opacityStepMm / (double(hi) - double(lo)) : 0.0;
        const double gf = options_.gradientFactor;
        impl->gradientRate = kKroesGradientScale * gf * gf * gf;
    }
    for (int a = 0; a < 3; ++a) {
        const int n = g.dims[a];
        impl->boxLo[a] = n > 1 ? 0.0 : -0.5;
        impl->boxHi[a] = n > 1 ? double(n - 1) : 0.5;
    }
    for (const auto& p : options_.clipPlanes) {
        impl->keep.push_back({p.point, p.normal});
        if (!p.shadowsFromRemoved) impl->lightKeep.push_back({p.point, p.normal});
    }
    if (options_.cropBox)
        for (int a = 0; a < 3; ++a) {
            glm::dvec3 n(0.0);
            n[a] = 1.0;
            const HalfSpace lo{options_.cropBox->min, n}, hi{options_.cropBox->max, -n};
            impl->keep.push_back(lo);
            impl->keep.push_back(hi);
            if (!options_.cropBox->shadowsFromRemoved) {
                impl->lightKeep.push_back(lo);
                impl->lightKeep.push_back(hi);
            }
        }
    impl->cellSize = impl->cells->cellSize();
    impl->counts = impl->cells->counts();
    for (std::size_t i = 0; i < impl->cells->size(); ++i)
        impl->globalMajorant = std::max(impl->globalMajorant, impl->cells->majorant(i));
    impl->majorantGrid = options_.majorantGrid;
    impl->dims = g.dims;
    impl->fineSize = impl->cellSize % kFineVoxels == 0 ? kFineVoxels : impl->cellSize;
    impl->fineCells = impl->cellSize / impl->fineSize;
    if (impl->majorantGrid) {
        impl->buildFine();
        impl->buildOctants();
    }
    const auto& busy = impl->cells->nonEmptyCellRange();
    if (glm::all(glm::lessThanEqual(busy[0], busy[1]))) {
        constexpr float kPad = 1e-3f;  // voxels
        impl->busyLo = glm::vec3(busy[0] * impl->cellSize) - kPad;
        impl->busyHi = glm::vec3((busy[1] + 1) * impl->cellSize) + kPad;
    }
    impl_ = std::move(impl);
}

bool PathTracer::keptInterval(const Ray& ray, double& t0, double& t1) const {
    return impl_->keptInterval(ray, t0, t1);
}

bool PathTracer::lightInterval(const Ray& ray, double& t0, double& t1) const {
    return impl_->lightInterval(ray, t0, t1);
}

std::optional<double> PathTracer::freeFlight(const Ray& ray, double t0, double t1,
                                             core::CounterRng& rng) const {
    Counters n;
    return impl_->volume->visit(
        [&](const auto& v) { return impl_->freeFlight(v, ray, t0, t1, rng, n); });
}

double PathTracer::transmittance(const Ray& ray, double maxT, core::CounterRng& rng) const {
    double t0 = 0.0, t1 = maxT;
    if (!impl_->lightInterval(ray, t0, t1)) return 1.0;
    Counters n;
    return impl_->volume->visit(
        [&](const auto& v) { return impl_->ratioTracking(v, ray, t0, t1, rng, n); });
}

std::vector<PathTracer::Piece> PathTracer::majorantPieces(const Ray& ray, double t0,
                                                          double t1) const {
    std::vector<Piece> out;
    if (!(t1 > t0)) return out;
    const Impl& im = *impl_;
    im.traverse(im.track(ray, t0, t1), [&](float sa, float sb, float m, float c, int) {
        if (m > 0.f) out.push_back({t0 + double(sa), t0 + double(sb), m, c});
        return true;
    });
    return out;
}

std::pair<std::uint64_t, std::uint64_t> PathTracer::checkSkipDistances() const {
    const Impl& im = *impl_;
    std::uint64_t checked = 0, bad = 0;
    // Every entry of an 8-per-cell table over a grid of n cells against nonEmpty(x, y, z): the
    // non-empty cells in each promised cube (its part inside the grid: cells past it count as
    // empty) by a summed-volume table.
    auto check = [&](const glm::ivec3& n, const std::uint8_t* oct, auto&& nonEmpty) {
        const glm::ivec3 m = n + 1;
        std::vector<std::uint32_t> sum(std::size_t(m.x) * m.y * m.z, 0);
        auto at = [&](int x, int y, int z) -> std::uint32_t& {
            return sum[std::size_t(x) +
                       std::size_t(m.x) * (std::size_t(y) + std::size_t(m.y) * std::size_t(z))];
        };
        for (int z = 0; z < n.z; ++z)
            for (int y = 0; y < n.y; ++y)
                for (int x = 0; x < n.x; ++x)
                    at(x + 1, y + 1, z + 1) = std::uint32_t(nonEmpty(x, y, z)) +
                                              at(x, y + 1, z + 1) + at(x + 1, y, z + 1) +
                                              at(x + 1, y + 1, z) - at(x, y, z + 1) -
                                              at(x, y + 1, z) - at(x + 1, y, z) + at(x, y, z);
        // Non-empty cells in [lo, hi] (inclusive).
        auto count = [&](const glm::ivec3& lo, const glm::ivec3& hi) {
            const glm::ivec3 a = lo, b = hi + 1;
            return std::int64_t(at(b.x, b.y, b.z)) - at(a.x, b.y, b.z) - at(b.x, a.y, b.z) -
                   at(b.x, b.y, a.z) + at(a.x, a.y, b.z) + at(a.x, b.y, a.z) + at(b.x, a.y, a.z) -
                   at(a.x, a.y, a.z);
        };
        for (int z = 0; z < n.z; ++z)
            for (int y = 0; y < n.y; ++y)
                for (int x = 0; x < n.x; ++x)
                    for (int o = 0; o < 8; ++o) {
                        const std::size_t i =
                            std::size_t(x) +
                            std::size_t(n.x) * (std::size_t(y) + std::size_t(n.y) * std::size_t(z));
                        const int d = oct[i * 8 + std::size_t(o)];
                        ++checked;
                        if (d == 0) {
                            bad += !nonEmpty(x, y, z);
                            continue;
                        }
                        const glm::ivec3 p(x, y, z);
                        glm::ivec3 lo, hi;
                        for (int a = 0; a < 3; ++a) {
                            const bool neg = (o >> a) & 1;
                            lo[a] = neg ? std::max(0, p[a] - (d - 1)) : p[a];
                            hi[a] = neg ? p[a] : std::min(n[a] - 1, p[a] + (d - 1));
                        }
                        bad += count(lo, hi) != 0;
                    }
    };
    if (!im.majorantGrid) return {0, 0};
    check(im.counts, im.octant.data(),
          [&](int x, int y, int z) { return im.cells->majorant(im.cells->index(x, y, z)) > 0.f; });
    const int fc = im.fineCells;
    const std::size_t block = std::size_t(fc) * fc * fc;
    for (const float* m : im.fineOf) {
        if (!m) continue;  // uniform: no entries
        check(glm::ivec3(fc), Impl::fineOctants(m, block), [&](int x, int y, int z) {
            return m[2 * (std::size_t(x) +
                          std::size_t(fc) * (std::size_t(y) + std::size_t(fc) * std::size_t(z)))] >
                   0.f;
        });
    }
    return {checked, bad};
}

float PathTracer::extinctionAt(const glm::dvec3& p) const {
    return impl_->volume->visit([&](const auto& v) { return impl_->sigma(v, impl_->indexOf(p)); });
}

std::size_t PathTracer::accelerationBytes() const {
    const Impl& im = *impl_;
    auto bytes = [](const auto& v) { return v.capacity() * sizeof(v[0]); };
    return bytes(im.fineSlot) + bytes(im.fineFirst) + bytes(im.fineLast) + bytes(im.fineOf) +
           bytes(im.blockMajorant) + bytes(im.blockControl) + bytes(im.fineChunks) +
           im.fineChunks.size() * im.fineChunkFloats * sizeof(float) +
           bytes(std::get<0>(im.corners)) + bytes(std::get<1>(im.corners)) +
           bytes(std::get<2>(im.corners)) + bytes(std::get<3>(im.corners)) + bytes(im.octant);
}

const optics::TfTable& PathTracer::table() const { return *impl_->table; }

const core::Volume& PathTracer::volume() const { return *impl_->volume; }

optics::TfSample PathTracer::mediumAt(const glm::dvec3& p) const {
    return impl_->volume->visit([&](const auto& v) {
        const glm::dvec3 ijk = impl_->indexOf(p);
        return impl_->table->lookup(v.sample(float(ijk.x), float(ijk.y), float(ijk.z)));
    });
}

double PathTracer::brdfProbabilityAt(const glm::dvec3& p, glm::dvec3* gradient) const {
    return impl_->volume->visit([&](const auto& v) {
        const glm::dvec3 ijk = impl_->indexOf(p);
        const glm::dvec3 gr = impl_->gradient(v, ijk);
        if (gradient) *gradient = gr;
        return impl_->brdfProbability(impl_->sigma(v, ijk), glm::length(gr));
    });
}

double PathTracer::autofocus(const render::Camera& camera) const {
    const render::Ray c = camera.generateAt(0.5 * camera.width(), 0.5 * camera.height());
    const Ray ray{c.origin, c.direction};
    const double along = glm::dot(c.direction, camera.forward());
    const core::Geometry& g = impl_->volume->geometry();
    double t0 = 0.0, t1 = INFINITY;
    if (impl_->keptInterval(ray, t0, t1)) {
        const double step =
            kAutofocusStepVoxels * std::min({g.spacing.x, g.spacing.y, g.spacing.z});
        double tau = 0.0;
        for (double t = t0; t < t1; t += step) {
            const double dt = std::min(step, t1 - t);
            const double s = extinctionAt(ray.origin + (t + 0.5 * dt) * ray.direction);
            if (tau + s * dt >= std::numbers::ln2)
                return (t + (std::numbers::ln2 - tau) / s) * along;
            tau += s * dt;
        }
    }
    const auto b = g.worldBounds();
    return std::max(glm::dot(0.5 * (b[0] + b[1]) - camera.eye(), camera.forward()), 1e-3);
}

Guides PathTracer::guides(const render::Camera& camera) const {
    const Impl& im = *impl_;
    const int w = camera.width(), h = camera.height();
    const std::size_t n = std::size_t(w) * std::size_t(h);
    Guides g;
    g.width = w;
    g.height = h;
    g.albedo.assign(n, glm::vec3(0.f));
    g.normal.assign(n, glm::vec3(0.f));
    g.depth.assign(n, 0.f);
    const core::Geometry& geo = im.volume->geometry();
    const double stepMm =
        kGuideStepVoxels * std::min({geo.spacing.x, geo.spacing.y, geo.spacing.z});
    // Escaping rays count at the depth of the volume box's farthest corner.
    double far = 0.0;
    const auto b = geo.worldBounds();
    for (int c = 0; c < 8; ++c) {
        const glm::dvec3 corner((c & 1) ? b[1].x : b[0].x, (c & 2) ? b[1].y : b[0].y,
                                (c & 4) ? b[1].z : b[0].z);
        far = std::max(far, glm::dot(corner - camera.eye(), camera.forward()));
    }
    // ∇ in world = toIndexᵀ · ∇ in index space.
    const glm::dmat3 gradToWorld = glm::transpose(im.toIndex);
    std::unique_ptr<tbb::global_control> limit;
    if (options_.threads > 0)
        limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      std::size_t(options_.threads));
    // The expectations along the rays through the pixel corners, (w + 1) × (h + 1).
    const int cw = w + 1, ch = h + 1;
    const std::size_t cn = std::size_t(cw) * std::size_t(ch);
    std::vector<glm::vec3> cAlbedo(cn), cNormal(cn);
    std::vector<float> cDepth(cn);
    im.volume->visit([&](const auto& view) {
        tbb::parallel_for(0, ch, [&](int y) {
            for (int x = 0; x < cw; ++x) {
                const render::Ray cr = camera.generateAt(x, y);
                const Ray ray{cr.origin, cr.direction};
                const double along = glm::dot(cr.direction, camera.forward());
                glm::dvec3 albedo(0.0), normal(0.0);
                double depth = 0.0, T = 1.0;
                double t0 = 0.0, t1 = INFINITY;
                if (im.keptInterval(ray, t0, t1)) {
                    const Track k = im.track(ray, t0, t1);
                    im.traverse(k, [&](float sa, float sb, float m, float, int) {
                        if (!(m > 0.f)) return true;
                        const int steps = std::max(1, int(std::ceil((sb - sa) / stepMm)));
                        const double dt = double(sb - sa) / steps;
                        for (int i = 0; i < steps; ++i) {
                            const double s = sa + (i + 0.5) * dt;
                            const glm::vec3 p = k.o + float(s) * k.d;
                            const optics::TfSample ts =
                                im.table->lookup(view.sample(p.x, p.y, p.z));
                            if (!(ts.extinction > 0.f)) continue;
                            const double wgt = T * -std::expm1(-double(ts.extinction) * dt);
                            const glm::dvec3 grad(
                                view.sample(p.x + 1.f, p.y, p.z) - view.sample(p.x - 1.f, p.y, p.z),
                                view.sample(p.x, p.y + 1.f, p.z) - view.sample(p.x, p.y - 1.f, p.z),
                                view.sample(p.x, p.y, p.z + 1.f) -
                                    view.sample(p.x, p.y, p.z - 1.f));
                            const glm::dvec3 gw = gradToWorld * grad;
                            const double len = glm::length(gw);
                            albedo += wgt * glm::dvec3(ts.albedo);
                            if (len > 0.0) normal += (wgt / len) * gw;
                            depth += wgt * (t0 + s) * along;
                            T -= wgt;
                            if (T < kGuideTransmittance) return false;
                        }
                        return true;
                    });
                }
                const std::size_t c = std::size_t(y) * cw + x;
                cAlbedo[c] = glm::vec3(albedo);
                cNormal[c] = glm::vec3(normal);
                cDepth[c] = float(depth + std::max(T, 0.0) * far);
            }
        });
    });
    // Each pixel: the mean of its four corners.
    tbb::parallel_for(0, h, [&](int y) {
        for (int x = 0; x < w; ++x) {
            const std::size_t p = std::size_t(y) * w + x, c = std::size_t(y) * cw + x;
            const std::size_t q[4] = {c, c + 1, c + cw, c + cw + 1};
            glm::vec3 a(0.f), nn(0.f);
            float z = 0.f;
            for (std::size_t k : q) {
                a += cAlbedo[k];
                nn += cNormal[k];
                z += cDepth[k];
            }
            g.albedo[p] = 0.25f * a;
            g.normal[p] = 0.25f * nn;
            g.depth[p] = 0.25f * z;
        }
    });
    return g;
}

core::ImageRGBA PathTracer::render(const render::Camera& pinhole, const core::Progress& progress,
                                   Stats* stats, core::ImageRGBA* stdError) const {
    render::Camera camera = pinhole;
    double focus = options_.focusMm;
    const bool lens = options_.apertureMm > 0.0;
    if (lens) {
        if (!(focus > 0.0)) focus = autofocus(pinhole);
        camera.setLens(options_.apertureMm, focus);
    }
    core::Stopwatch clock;
    const Impl& im = *impl_;
    const int w = camera.width(), h = camera.height();
    const std::size_t pixels = std::size_t(w) * std::size_t(h);
    // Per pixel, in double: Σ rgb, Σ rgb², Σ luminance², Σ alpha.
    std::vector<double> sum(pixels * 3, 0.0), sumSq(pixels * 3, 0.0), lumSq(pixels, 0.0),
        alpha(pixels, 0.0);
    std::vector<std::shared_ptr<const lights::Light>> lightList = options_.lights;
    if (lightList.empty())
        lightList.push_back(render::headlight(camera, render::kVolumetricHeadlightIrradiance));
    const bool anyHittable = std::any_of(lightList.begin(), lightList.end(),
                                         [](const auto& l) { return !l->isDelta(); });
    const float g = options_.phaseG;
    const bool phaseChannel = im.table->hasPhaseG();  // the TF's g replaces options_.phaseG
    const glm::dvec3 bg(options_.background);
    std::atomic<std::uint64_t> paths{0}, real{0}, null{0}, shadow{0}, violations{0}, budget{0},
        surfaceEvents{0};

    // One sample of pixel p: accumulates rgb, rgb² and coverage.
    auto trace = [&](const auto& view, int x, int y, int s, Counters& n) {
        const std::size_t p = std::size_t(y) * std::size_t(w) + std::size_t(x);
        core::CounterRng rng(core::hashCounters(p, std::uint64_t(s), 0x7074, options_.seed));
        const double jx = options_.pixelJitter ? rng.uniformDouble() : 0.5;
        const double jy = options_.pixelJitter ? rng.uniformDouble() : 0.5;
        // Lens samples only with a lens: a pinhole image keeps its random numbers (and pixels).
        const double lu = lens ? rng.uniformDouble() : 0.0, lv = lens ? rng.uniformDouble() : 0.0;
        const render::Ray cr = camera.generateThroughLens(x + jx, y + jy, lu, lv);
        Ray ray{cr.origin, cr.direction};
        glm::dvec3 L(0.0), beta(1.0);
        double covered = 0.0, phasePdf = 0.0;
        for (int bounce = 0;; ++bounce) {
            double t0 = 0.0, t1 = INFINITY;
            const bool kept = im.keptInterval(ray, t0, t1);
            float value = 0.f;  // the value at the collision, from the flight's own sample
            const std::optional<double> hit =
                kept ? im.freeFlight(view, ray, t0, t1, rng, n, &value) : std::nullopt;
            if (!hit) {
                if (bounce == 0) {
                    L += bg;  // the camera sees the background through the volume
                } else {
                    // The phase-sampled direction meets the lights a ray can hit (MIS with NEE).
                    // Past the kept region, removed matter that still occludes (section view)
                    // attenuates it, as it does the shadow rays.
                    const glm::vec3 wi(ray.direction);
                    double T = 1.0;
                    bool occluderTested = false;
                    for (const auto& light : lightList) {
                        if (light->isDelta()) continue;
                        const glm::dvec3 le(light->radiance(ray.origin, wi));
                        if (le == glm::dvec3(0.0)) continue;
                        if (!occluderTested) {
                            occluderTested = true;
                            double l0 = 0.0, l1 = INFINITY;
                            if (im.lightInterval(ray, l0, l1)) {
                                const double from = kept ? std::max(l0, t1) : l0;
                                if (l1 > from) T = im.ratioTracking(view, ray, from, l1, rng, n);
                            }
                        }
                        if (!(T > 0.0)) break;
                        L += beta * le * (T * powerHeuristic(phasePdf, light->pdf(ray.origin, wi)));
                    }
                }
                break;
            }
            if (bounce == 0) covered = 1.0;
            const glm::dvec3 x3 = ray.origin + *hit * ray.direction;
            const optics::TfSample ts = im.table->lookup(value);
            const glm::dvec3 albedo(ts.albedo);
            L += beta * (1.0 - albedo) * glm::dvec3(ts.emission);  // ARCHITECTURE §1: (1 − a)·e
            // Phase or BRDF for this event (hybrid scattering, header comment). Only a P_brdf
            // strictly between 0 and 1 draws a random number, so phase-only paths keep theirs.
            float gHere = g;
            bool surface = false;
            SurfaceMaterial mat;
            glm::dvec3 nrm(0.0);
            const glm::dvec3 wo = -ray.direction;
            if (im.scattering != Scattering::Phase || phaseChannel) {
                const optics::TfSurface sf = im.table->surface(value);
                if (phaseChannel) gHere = sf.phaseG;
                if (im.scattering != Scattering::Phase) {
                    const glm::dvec3 grad = im.gradient(view, im.indexOf(x3));
                    const double len = glm::length(grad);
                    const double pb = im.brdfProbability(ts.extinction, len);
                    if (pb > 0.0 && (pb >= 1.0 || rng.uniformDouble() < pb)) {
                        surface = true;
                        nrm = grad / len;
                        if (glm::dot(nrm, wo) < 0.0) nrm = -nrm;
                        mat = {albedo, glm::dvec3(sf.specular), double(sf.roughness)};
                        ++n.surface;
                    }
                }
            }
            if (!surface) {
                beta *= albedo;
                if (beta == glm::dvec3(0.0)) break;
            }
            const bool continues = bounce + 1 < options_.maxBounces;
            // Transmittance from x3 along wi up to `distance` (mm; ∞ for environment lights):
            // ratio tracking over the part the light's interval keeps (clip planes, box).
            auto transmittance = [&](const glm::dvec3& wi, double distance) {
                double t0 = 0.0, t1 = distance;
                const Ray sr{x3, wi};
                return im.lightInterval(sr, t0, t1) ? im.ratioTracking(view, sr, t0, t1, rng, n)
                                                    : 1.0;
            };
            // Next-event estimation towards every light; MIS weights only when the path also
            // continues by phase (BRDF) sampling (which can then hit the same area/environment
            // light).
            for (const auto& light : lightList) {
                const glm::vec2 u(rng.uniform(), rng.uniform());
                const lights::LightSample ls = light->sample(x3, u);
                if (!(ls.pdf > 0.f)) continue;
                const glm::dvec3 wi(ls.wi);
                if (surface) {
                    // f·|n·wi| of the BRDF in place of the phase function.
                    const double cosI = glm::dot(nrm, wi);
                    if (!(cosI > 0.0)) continue;
                    const glm::dvec3 f = evalBrdf(mat, nrm, wo, wi) * cosI;
                    if (f == glm::dvec3(0.0)) continue;
                    const double T = transmittance(wi, double(ls.distance));
                    if (!(T > 0.0)) continue;
                    glm::dvec3 c = beta * f * T * glm::dvec3(ls.value);
                    if (!ls.delta) {
                        // Always MIS: a BRDF event also samples its lobe toward the lights when
                        // the path ends here (below).
                        c /= double(ls.pdf);
                        c *= powerHeuristic(ls.pdf, pdfBrdf(mat, nrm, wo, wi));
                    }
                    L += c;
                    continue;
                }
                const double phase = henyeyGreenstein(float(glm::dot(ray.direction, wi)), gHere);
                const double T = transmittance(wi, double(ls.distance));
                if (!(T > 0.0)) continue;
                glm::dvec3 c = beta * (phase * T) * glm::dvec3(ls.value);
                if (!ls.delta) {
                    // MIS: the path's next direction (or, where it ends, one phase direction
                    // below) samples the phase function toward the same light.
                    c /= double(ls.pdf);
                    c *= powerHeuristic(ls.pdf, phase);
                }
                L += c;
            }
            if (!continues) {
                // Where the path ends, one direction drawn from the event's own lobe toward the
                // area and environment lights (MIS with the light samples above), weight w =
                // f·cos/pdf; the ray sees the transmittance the shadow rays see (ratio tracking
                // over lightInterval).
                auto lobeTowardLights = [&](const glm::dvec3& dir, double pdf,
                                            const glm::dvec3& w) {
                    const glm::vec3 wi(dir);
                    double T = -1.0;  // traced on first need
                    for (const auto& light : lightList) {
                        if (light->isDelta()) continue;
                        const glm::dvec3 le(light->radiance(x3, wi));
                        if (le == glm::dvec3(0.0)) continue;
                        if (T < 0.0) T = transmittance(dir, INFINITY);
                        if (!(T > 0.0)) break;
                        L += w * le * (T * powerHeuristic(pdf, light->pdf(x3, wi)));
                    }
                };
                // A phase event: a large area light is what sampling its area estimates worst —
                // under rect lights of 1e4–1e6 mm the single-scattered image read 4–50× too dark
                // at 64 spp, relative error up to 39 (probe, 7 December). Only where such a light
                // exists, so that renders under delta lights draw the same random numbers as
                // before. HG is sampled exactly: f/pdf = 1.
                if (!surface && anyHittable) {
                    const glm::dvec3 next =
                        sampleHenyeyGreenstein(ray.direction, gHere, rng.uniform(), rng.uniform());
                    lobeTowardLights(
                        next, henyeyGreenstein(float(glm::dot(ray.direction, next)), gHere), beta);
                }
                // A BRDF event: a glossy lobe under an environment map is what light sampling
                // alone estimates worst.
                if (surface) {
                    const double u0 = rng.uniformDouble(), u1 = rng.uniformDouble(),
                                 u2 = rng.uniformDouble();
                    const BrdfSample bs = sampleBrdf(mat, nrm, wo, u0, u1, u2);
                    if (bs.pdf > 0.0)
                        lobeTowardLights(bs.wi, bs.pdf,
                                         beta * bs.f * (glm::dot(nrm, bs.wi) / bs.pdf));
                }
                break;
            }
            if (bounce + 1 >= options_.rouletteAfter) {
                const double q = std::clamp(std::max({beta.x, beta.y, beta.z}), 0.05, 1.0);
                if (rng.uniformDouble() >= q) break;
                beta /= q;
            }
            if (surface) {
                const double u0 = rng.uniformDouble(), u1 = rng.uniformDouble(),
                             u2 = rng.uniformDouble();
                const BrdfSample bs = sampleBrdf(mat, nrm, wo, u0, u1, u2);
                if (!(bs.pdf > 0.0)) break;
                beta *= bs.f * (glm::dot(nrm, bs.wi) / bs.pdf);
                if (beta == glm::dvec3(0.0)) break;
                phasePdf = bs.pdf;
                ray = Ray{x3, bs.wi};
                continue;
            }
            const glm::dvec3 next =
                sampleHenyeyGreenstein(ray.direction, gHere, rng.uniform(), rng.uniform());
            phasePdf = henyeyGreenstein(float(glm::dot(ray.direction, next)), gHere);
            ray = Ray{x3, next};
        }
        double lum = 0.0;
        for (int c = 0; c < 3; ++c) {
            const double v = std::isfinite(L[c]) ? L[c] : 0.0;
            sum[p * 3 + c] += v;
            sumSq[p * 3 + c] += v * v;
            lum += core::kLuminanceWeights[c] * v;
        }
        lumSq[p] += lum * lum;
        alpha[p] += covered;
    };

    std::unique_ptr<tbb::global_control> limit;
    if (options_.threads > 0)
        limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      std::size_t(options_.threads));
    // Samples taken per pixel (all equal without adaptive sampling) and, with it, the samples
    // each pixel takes in the coming pass and its carried fractional share.
    std::vector<std::int32_t> count(pixels, 0), take(pixels, 0);
    std::vector<double> credit, sigma2, weight;
    // Pixel p's luminance mean and the mean square of its samples' deviation from it (channels
    // summed per sample, so their correlation counts), from its own samples.
    struct Moments {
        double mean, spread;
    };
    auto moments = [&](std::size_t p) {
        const double n = count[p];
        double m = 0.0;
        for (int c = 0; c < 3; ++c) m += core::kLuminanceWeights[c] * sum[p * 3 + c];
        m /= n;
        return Moments{m, std::max(0.0, lumSq[p] / n - m * m)};
    };
    // The image's relative error (Stats::relativeStdError): the variance of each covered pixel's
    // mean in each of R, G and B, averaged over them, over the mean covered RGB value — the NRMS
    // of the convergence benchmark (and the path tracer's issue), whose error is RGB too.
    // Over covered pixels and R, G, B: Σ variance of the pixel's mean, Σ mean, Σ mean², count.
    struct CoveredSums {
        double var = 0.0, mean = 0.0, square = 0.0;
        std::size_t values = 0;
    };
    auto coveredSums = [&] {
        CoveredSums t;
        for (std::size_t p = 0; p < pixels; ++p) {
            if (!(alpha[p] > 0.0)) continue;
            const double n = count[p];
            for (int c = 0; c < 3; ++c) {
                const double m = sum[p * 3 + c] / n;
                t.var += std::max(0.0, sumSq[p * 3 + c] / n - m * m) / std::max(1.0, n - 1.0);
                t.mean += m;
                t.square += m * m;
                ++t.values;
            }
        }
        return t;
    };
    auto relativeError = [&] {
        const CoveredSums t = coveredSums();
        return t.values && t.mean > 0.0
                   ? std::sqrt(t.var / double(t.values)) / (t.mean / double(t.values))
                   : 0.0;
    };
    // Adaptive sampling (Options::adaptive): the pass's samples, `perPixel` × pixels in all, shared
    // in proportion to each pixel's noise weight — √(3×3 mean of the one-sample luminance
    // variance), floored at kAdaptiveFloor of the mean weight — through a carried credit, so over
    // the passes a pixel's count follows its weight (rounding never loses a sample's share).
    // Serial sums in pixel order: the same allocation for any thread count.
    auto allocate = [&](int perPixel) {
        sigma2.resize(pixels);
        weight.resize(pixels);
        for (std::size_t p = 0; p < pixels; ++p) {
            const double n = count[p];
            sigma2[p] = moments(p).spread * n / std::max(1.0, n - 1.0);  // one sample's variance
        }
        double total = 0.0;
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                double v = 0.0;
                int taps = 0;
                for (int yy = std::max(0, y - 1); yy <= std::min(h - 1, y + 1); ++yy)
                    for (int xx = std::max(0, x - 1); xx <= std::min(w - 1, x + 1); ++xx, ++taps)
                        v += sigma2[std::size_t(yy) * std::size_t(w) + std::size_t(xx)];
                const double wt = std::sqrt(v / taps);
                weight[std::size_t(y) * std::size_t(w) + std::size_t(x)] = wt;
                total += wt;
            }
        const double budget = double(perPixel) * double(pixels);
        const int cap = kAdaptiveMaxPassFactor * perPixel;
        if (!(total > 0.0) || !std::isfinite(total)) {
            std::fill(take.begin(), take.end(), perPixel);  // no noise anywhere: uniform
            return;
        }
        const double floorWeight = kAdaptiveFloor * total / double(pixels);
        double floored = 0.0;
        for (double& wt : weight) floored += (wt = std::max(wt, floorWeight));
        for (std::size_t p = 0; p < pixels; ++p) {
            credit[p] += budget * weight[p] / floored;
            const int k = int(std::min(std::floor(credit[p]), double(cap)));
            take[p] = k;
            credit[p] = std::min(credit[p] - k, double(cap));
        }
    };
    int done = 0;
    double error = 0.0;
    bool reached = false;
    // The stage's clock starts here (a progress line's elapsed time and estimate count from the
    // first report), not after the first pass.
    progress.report("pathtrace", 0.0, "0 spp");
    // Under a time cap the first pass is kFirstCappedPassSamples per pixel (a 4-spp first pass
    // ran 10.7 s under a 2-s cap with one global majorant), the passes after
    // it shrink to the samples per pixel that fit in the time left at the last pass's seconds
    // per sample per pixel (an adaptive pass costs more than a uniform one: the rate follows the
    // passes), and the render stops when not even half of one fits — so it ends within about
    // one sample per pixel of the cap, not a whole pass. The uniform warm-up still ends at
    // exactly kAdaptiveWarmupSamples, so the samples drawn are those of an uncapped render.
    double lastPassSeconds = 0.0;
    int lastPassSamples = 0;
    while (done < options_.samplesPerPixel) {
        int pass = kSamplesPerPass;
        if (options_.maxSeconds > 0.0 && lastPassSamples == 0) {
            pass = kFirstCappedPassSamples;
        } else if (options_.maxSeconds > 0.0) {
            const double perSample = lastPassSeconds / lastPassSamples;
            const double fits = (options_.maxSeconds - clock.seconds()) / perSample;
            if (!(fits >= 0.5)) break;
            // Clamped as a double: a long cap over a small image fits more than INT_MAX.
            pass = int(std::clamp(fits, 1.0, double(kSamplesPerPass)));
            // The first adaptive pass after the uniform warm-up costs more per sample (its
            // samples go to the covered pixels) than the rate just measured: one sample per
            // pixel, whose own rate then sizes the passes after it.
            if (options_.adaptive && done == kAdaptiveWarmupSamples) pass = 1;
            if (options_.adaptive && done < kAdaptiveWarmupSamples)
                pass = std::min(pass, kAdaptiveWarmupSamples - done);
        }
        const int s1 = std::min(options_.samplesPerPixel, done + pass);
        const double passStart = clock.seconds();
        if (options_.adaptive && done >= kAdaptiveWarmupSamples) {
            if (credit.empty()) credit.assign(pixels, 0.0);
            allocate(s1 - done);
        } else {
            std::fill(take.begin(), take.end(), s1 - done);
        }
        tbb::parallel_for(tbb::blocked_range2d<int>(0, h, 8, 0, w, 8), [&](const auto& r) {
            Counters n;
            std::uint64_t taken = 0;
            im.volume->visit([&](const auto& view) {
                for (int y = r.rows().begin(); y < r.rows().end(); ++y)
                    for (int x = r.cols().begin(); x < r.cols().end(); ++x) {
                        const std::size_t p = std::size_t(y) * std::size_t(w) + std::size_t(x);
                        const int first = count[p], last = first + take[p];
                        for (int s = first; s < last; ++s) trace(view, x, y, s, n);
                        count[p] = last;
                        taken += std::uint64_t(last - first);
                    }
            });
            paths += taken;
            real += n.real, null += n.null, shadow += n.shadow, violations += n.violations;
            budget += n.budget;
            surfaceEvents += n.surface;
        });
        lastPassSamples = s1 - done;
        done = s1;
        // One sample per pixel has no spread to estimate its error from: unknown, not 0 %.
        error = done >= 2 ? relativeError() : std::numeric_limits<double>::quiet_NaN();
        lastPassSeconds = clock.seconds() - passStart;
        // Progress: the largest of the spp fraction, the error's (error ∝ 1/√n, so the target
        // needs about n·(error/target)² samples) and the time cap's.
        double fraction = double(done) / options_.samplesPerPixel;
        if (options_.targetError > 0.0 && error > 0.0)
            fraction = std::max(fraction, std::min(1.0, (options_.targetError / error) *
                                                            (options_.targetError / error)));
        if (options_.maxSeconds > 0.0)
            fraction = std::max(fraction, std::min(1.0, clock.seconds() / options_.maxSeconds));
        char text[96];
        if (std::isnan(error))
            std::snprintf(text, sizeof text, "%d spp, error unknown", done);
        else
            std::snprintf(text, sizeof text, "%d spp, error %.2f%%", done, 100.0 * error);
        progress.report("pathtrace", fraction, text);
        if (options_.targetError > 0.0 && done >= kMinSamplesForErrorStop &&
            error <= options_.targetError) {
            reached = true;
            break;
        }
        if (options_.maxSeconds > 0.0 && clock.seconds() >= options_.maxSeconds) break;
    }

    core::ImageRGBA film(w, h);
    if (stdError) *stdError = core::ImageRGBA(w, h);
    for (std::size_t p = 0; p < pixels; ++p) {
        const double n = count[p];
        float* out = film.pixels.data() + p * 4;
        for (int c = 0; c < 3; ++c) {
            const double mean = sum[p * 3 + c] / n;
            const double var =
                std::max(0.0, sumSq[p * 3 + c] / n - mean * mean) / std::max(1.0, n - 1.0);
            out[c] = float(mean);
            // One sample has no spread: its error is unknown (NaN), not the 1e-11 of rounding
            // that read as "exact" (probe; the stats said null).
            if (stdError)
                stdError->pixels[p * 4 + c] =
                    n >= 2.0 ? float(std::sqrt(var)) : std::numeric_limits<float>::quiet_NaN();
        }
        out[3] = float(alpha[p] / n);
        if (stdError) stdError->pixels[p * 4 + 3] = 1.f;
    }
    if (stats) {
        stats->samplesPerPixel = done;
        const auto [fewest, most] = std::minmax_element(count.begin(), count.end());
        stats->minPixelSamples = pixels ? *fewest : 0;
        stats->maxPixelSamples = pixels ? *most : 0;
        stats->adaptive = options_.adaptive;
        stats->paths = paths;
        stats->realCollisions = real;
        stats->nullCollisions = null;
        stats->shadowRays = shadow;
        stats->majorantViolations = violations;
        stats->budgetExceeded = budget;
        stats->surfaceEvents = surfaceEvents;
        stats->seconds = clock.seconds();
        stats->accelerationBytes = accelerationBytes();
        stats->relativeStdError = error;
        // ErrorStats::nrmse's normalisation (the reference's RMS, not its mean) over the same
        // covered pixels and channels: what a perfect image's nrmse against this one would be.
        const CoveredSums t = coveredSums();
        stats->expectedNrmse = std::isnan(error) ? error
                               : t.square > 0.0  ? std::sqrt(t.var / t.square)
                                                 : 0.0;
        stats->targetReached = reached;
        stats->focusMm = lens ? focus : 0.0;
        stats->autofocused = lens && !(options_.focusMm > 0.0);
    }
    return film;
}

}  // namespace voxlight::pathtrace
