// SPDX-License-Identifier: MIT
#pragma once
// The templated per-ray marchers behind RayCaster (include only from .cpp files of render/ and of
// shading models that reuse the traversal). Everything here is inlined into tile loops that were
// dispatched once on the voxel type (View) and the shader type (Shader).
#include <algorithm>
#include <cmath>
#include <type_traits>
#include <utility>
#if defined(__SSE4_1__)
#include <smmintrin.h>
#endif
#if defined(__AVX2__)
#include <immintrin.h>
#endif

#include <Eigen/Core>

#include "render/footprint.h"
#include "render/ray_caster.h"

namespace voxlight::render::detail {

/// e^x without a library call (a call spills the marcher's live vector registers): Eigen's
/// packet exp (Cephes polynomial, ≈ 1 ulp) on one lane.
[[gnu::always_inline]] inline float expInline(float x) {
    return Eigen::internal::pfirst(
        Eigen::internal::pexp(Eigen::internal::pset1<Eigen::internal::Packet4f>(x)));
}

/// a·b + c rounded once where the target has FMA (then SampleBatch's vector lanes and the scalar
/// sampling agree bit for bit at any optimisation level), else as written.
[[gnu::always_inline]] inline float fmaF(float a, float b, float c) {
#if defined(__FMA__)
    return std::fma(a, b, c);
#else
    return a * b + c;
#endif
}

/// Below this optical depth opacity() uses the series (see there).
inline constexpr float kOpacitySeriesTau = 0.01f;

/// Segment opacity α = 1 − e^(−τ) for τ ≥ 0 (∞ gives 1). Thin segments use the Taylor series
/// τ·(1 − τ/2·(1 − τ/3)) (truncation τ⁴/24: relative 4e-8 at τ = 0.01): 1 − e^(−τ) in float
/// loses the digits of a small α to the rounding of e^(−τ) near 1 (6e-8 absolute, i.e. 0.6 % at
/// τ = 1e-5).
[[gnu::always_inline]] inline float opacity(float tau) {
    if (tau < kOpacitySeriesTau) return tau * (1.f - 0.5f * tau * (1.f - tau * (1.f / 3.f)));
    return 1.f - expInline(-tau);
}

/// Mean depth of the first scattering event inside a homogeneous segment of length dt and optical
/// depth τ: the α-weighted mean of t, ∫₀^dt t σ e^(−σt) dt / α = dt·(1/τ − 1/(e^τ − 1)) — dt/2 for
/// a thin segment (series 1/2 − τ/12 below τ = 0.01), 1/σt for a dense one. A visibility that
/// varies linearly along the segment has its α-weighted mean exactly there.
[[gnu::always_inline]] inline float meanScatterDepth(float tau, float dt) {
    if (tau < kOpacitySeriesTau) return dt * (0.5f - tau * (1.f / 12.f));
    if (tau > 80.f) return dt / tau;  // e^τ overflows float near 88
    return dt * (1.f / tau - 1.f / std::expm1(tau));
}

/// Whether shader S wants its segments shaded at the mean scattering depth (S::kScatterAtMeanDepth;
/// default false: at the segment's back end, where the gradient normal is taken).
template <class S>
constexpr bool scattersAtMeanDepth() {
    if constexpr (requires { S::kScatterAtMeanDepth; })
        return S::kScatterAtMeanDepth;
    else
        return false;
}

/// Sample points of a ray: t_0 = tNear, t_i = tNear + (j + i − 1)·Δ clamped to tFar, last = tFar.
struct SampleLattice {
    float tNear, tFar, step, jitter;
    std::int64_t last;
    SampleLattice(const RaySegment& r, float stepMm)
        : tNear(r.tNear), tFar(r.tFar), step(stepMm), jitter(r.jitter) {
        last = 1 + std::int64_t(std::ceil((tFar - tNear) / step - jitter));
        if (last < 1) last = 1;
    }
    float t(std::int64_t i) const {
        if (i <= 0) return tNear;
        const float t = fmaF(jitter + float(i - 1), step, tNear);
        return i >= last || t > tFar ? tFar : t;
    }
    /// Largest i with t(i) ≤ x.
    std::int64_t before(float x) const {
        if (x < tNear + jitter * step) return 0;
        const std::int64_t i = 1 + std::int64_t(std::floor((x - tNear) / step - jitter));
        return i < last ? (i > 0 ? i : 0) : last;
    }
    /// Smallest i with t(i) ≥ x.
    std::int64_t after(float x) const {
        const std::int64_t i = before(x);
        return i < last && t(i) < x ? i + 1 : i;
    }
};

/// Trilinear interpolation of the precomputed central differences of a cell whose lower corner
/// entry is q, with weights (fx, fy, fz) and corner strides (di, dj, dk), scaled to a world
/// gradient. With SSE4.1 each corner's (Δi, Δj, Δk, 0) is one 64-bit load widened to four floats
/// and the seven lerps run on all three components at once (the same arithmetic per component as
/// the scalar path).
[[gnu::always_inline]] inline glm::vec3 gradientAtCell(const GradientEntry* q, float slope,
                                                       float fx, float fy, float fz, std::size_t di,
                                                       std::size_t dj, std::size_t dk,
                                                       const glm::mat3& m) {
#if defined(__SSE4_1__)
    auto corner = [&](std::size_t o) {
        return _mm_cvtepi32_ps(
            _mm_cvtepi16_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(q + o))));
    };
    auto lerp = [](__m128 a, __m128 b, __m128 f) {
        return _mm_add_ps(a, _mm_mul_ps(f, _mm_sub_ps(b, a)));
    };
    const __m128 vx = _mm_set1_ps(fx), vy = _mm_set1_ps(fy), vz = _mm_set1_ps(fz);
    const __m128 c00 = lerp(corner(0), corner(di), vx);
    const __m128 c10 = lerp(corner(dj), corner(dj + di), vx);
    const __m128 c01 = lerp(corner(dk), corner(dk + di), vx);
    const __m128 c11 = lerp(corner(dk + dj), corner(dk + dj + di), vx);
    const __m128 r = lerp(lerp(c00, c10, vy), lerp(c01, c11, vy), vz);
    alignas(16) float out[4];
    _mm_store_ps(out, r);
    return m * (slope * glm::vec3(out[0], out[1], out[2]));
#else
    auto lerpX = [&](const GradientEntry& a, const GradientEntry& b) {
        return glm::vec3(float(a[0]) + fx * (float(b[0]) - float(a[0])),
                         float(a[1]) + fx * (float(b[1]) - float(a[1])),
                         float(a[2]) + fx * (float(b[2]) - float(a[2])));
    };
    const glm::vec3 c00 = lerpX(q[0], q[di]), c10 = lerpX(q[dj], q[dj + di]);
    const glm::vec3 c01 = lerpX(q[dk], q[dk + di]), c11 = lerpX(q[dk + dj], q[dk + dj + di]);
    const glm::vec3 c0 = c00 + fy * (c10 - c00), c1 = c01 + fy * (c11 - c01);
    return m * (slope * (c0 + fz * (c1 - c0)));
#endif
}

struct CellCorner {
    int i = 0, j = 0, k = 0;  ///< the cell's lower corner
};
struct NoCellCorner {};

/// The hot-loop form of core::VolumeView::sample: the grid constants (clamp limits, corner strides)
/// are computed once per ray instead of per sample, and a sample is split into locate() (cell and
/// weights) and value(), so that the gradient table can reuse the cell of the value sample at the
/// same point. Same clamping, weights and lerps as core::VolumeView::sample, with the
/// multiply-adds fused where the target has FMA (fmaF: what an optimising build contracts them to
/// anyway), so that SampleBatch's lanes equal it bit for bit in any build.
/// kWithCorner: cells also carry their lower corner (i, j, k), for BrickedGradients (kept out of
/// the cell otherwise: the marcher stores every sample's cell).
template <class View, bool kWithCorner = false>
struct CellSampler {
    using Elem = std::remove_cv_t<std::remove_pointer_t<decltype(View::data)>>;
    struct Cell : std::conditional_t<kWithCorner, CellCorner, NoCellCorner> {
        std::size_t offset = 0;  ///< linear index of the cell's lower corner
        float fx = 0.f, fy = 0.f, fz = 0.f;
    };
    const Elem* data;
    std::size_t sy, sz, di, dj, dk;
    float hx, hy, hz;  ///< largest index per axis, as float
    int mi, mj, mk;    ///< largest lower-corner index per axis
    float slope, intercept;

    explicit CellSampler(const View& v)
        : data(v.data),
          sy(v.sy),
          sz(v.sz),
          di(v.nx > 1 ? 1 : 0),
          dj(v.ny > 1 ? v.sy : 0),
          dk(v.nz > 1 ? v.sz : 0),
          hx(float(v.nx - 1)),
          hy(float(v.ny - 1)),
          hz(float(v.nz - 1)),
          mi(v.nx - 2 < 0 ? 0 : v.nx - 2),
          mj(v.ny - 2 < 0 ? 0 : v.ny - 2),
          mk(v.nz - 2 < 0 ? 0 : v.nz - 2),
          slope(v.slope),
          intercept(v.intercept) {}

    [[gnu::always_inline]] Cell locate(const glm::vec3& p) const {
        const float x = std::min(std::max(p.x, 0.f), hx);
        const float y = std::min(std::max(p.y, 0.f), hy);
        const float z = std::min(std::max(p.z, 0.f), hz);
        const int i = std::min(int(x), mi), j = std::min(int(y), mj), k = std::min(int(z), mk);
        Cell c;
        c.offset = std::size_t(i) + sy * std::size_t(j) + sz * std::size_t(k);
        c.fx = x - float(i);
        c.fy = y - float(j);
        c.fz = z - float(k);
        if constexpr (kWithCorner) c.i = i, c.j = j, c.k = k;
        return c;
    }
    [[gnu::always_inline]] float value(const Cell& c) const {
        const Elem* p = data + c.offset;
        auto lerp = [](float a, float b, float f) { return fmaF(f, b - a, a); };
        const float c00 = lerp(float(p[0]), float(p[di]), c.fx);
        const float c10 = lerp(float(p[dj]), float(p[dj + di]), c.fx);
        const float c01 = lerp(float(p[dk]), float(p[dk + di]), c.fx);
        const float c11 = lerp(float(p[dk + dj]), float(p[dk + dj + di]), c.fx);
        const float c0 = lerp(c00, c10, c.fy), c1 = lerp(c01, c11, c.fy);
        return fmaF(slope, lerp(c0, c1, c.fz), intercept);
    }
};

/// Lattice samples taken eight at a time (AVX2): positions, cells and trilinear values of
/// samples i … i + 7 of a ray in vector registers, the corner pairs (x, x + 1) of each row fetched
/// by one 32-bit gather. Same arithmetic per lane as SampleLattice::t, DvrMarcher::at,
/// CellSampler::locate and CellSampler::value (whose multiply-adds are fmaF), so equal bit for
/// bit. For 8- and 16-bit voxels on grids with more than one voxel along i; otherwise kSupported
/// is false or usable() is, and the marcher takes samples one by one.
#if defined(__AVX2__) && defined(__FMA__)
template <class View, bool kWithCorner>
struct SampleBatch {
    using Sampler = CellSampler<View, kWithCorner>;
    using Elem = typename Sampler::Elem;
    using Cell = typename Sampler::Cell;
    static constexpr bool kSupported = std::is_integral_v<Elem> && sizeof(Elem) <= 2;
    static constexpr int kLanes = 8;

    alignas(32) float t[kLanes], s[kLanes];
    alignas(32) float fx[kLanes], fy[kLanes], fz[kLanes];
    alignas(32) std::int32_t offset[kLanes], ci[kLanes], cj[kLanes], ck[kLanes];
    /// Lanes whose segment from the previous lane's sample (lane 0: from `before`) is certainly
    /// transparent (TfTable::transparentSegment), as a bit mask.
    unsigned transparent = 0;

    [[gnu::always_inline]] Cell cell(int l) const {
        Cell c;
        c.offset = std::size_t(std::uint32_t(offset[l]));
        c.fx = fx[l];
        c.fy = fy[l];
        c.fz = fz[l];
        if constexpr (kWithCorner) c.i = ci[l], c.j = cj[l], c.k = ck[l];
        return c;
    }

    /// Whether a ray through `sampler`'s grid can be batched: gathers read 4 bytes from a
    /// clamped address, so the volume needs ≥ 4 bytes and < 2³¹ of them, and the pair trick
    /// needs neighbours along i.
    static bool usable(const Sampler& sm, std::size_t voxels) {
        const std::size_t bytes = voxels * sizeof(Elem);
        return kSupported && sm.di == 1 && bytes >= 4 && bytes < (std::size_t(1) << 31);
    }

    /// Samples i … i + 7 (indices ≥ 1; those past lat.last sit at tFar, like SampleLattice::t).
    /// `before`: the value of the sample before lane 0; `zeroBelow`/`zeroAbove`: the TF's
    /// transparent tails (TfTable::transparentSegment).
    [[gnu::always_inline]] void take(std::int64_t i, const SampleLattice& lat, const RaySegment& r,
                                     const Sampler& sm, std::size_t voxels, float before,
                                     float zeroBelow, float zeroAbove) {
        const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        const __m256i idx = _mm256_add_epi32(_mm256_set1_epi32(int(i)), lane);
        // t = tNear + (jitter + (i − 1))·step, clamped to tFar past the last sample.
        const __m256 k = _mm256_cvtepi32_ps(_mm256_sub_epi32(idx, _mm256_set1_epi32(1)));
        __m256 tv = _mm256_fmadd_ps(_mm256_add_ps(_mm256_set1_ps(lat.jitter), k),
                                    _mm256_set1_ps(lat.step), _mm256_set1_ps(lat.tNear));
        const __m256 tFar = _mm256_set1_ps(lat.tFar);
        const __m256i past = _mm256_cmpgt_epi32(
            idx, _mm256_set1_epi32(int(std::min<std::int64_t>(lat.last - 1, INT32_MAX))));
        const __m256 beyond =
            _mm256_or_ps(_mm256_castsi256_ps(past), _mm256_cmp_ps(tv, tFar, _CMP_GT_OQ));
        tv = _mm256_blendv_ps(tv, tFar, beyond);
        _mm256_store_ps(t, tv);
        // locate(): clamp to the grid, lower corner, weights.
        auto axis = [&](float o, float d, float h, int mx, __m256i& ci, __m256& f) {
            __m256 x = _mm256_fmadd_ps(tv, _mm256_set1_ps(d), _mm256_set1_ps(o));
            x = _mm256_min_ps(_mm256_max_ps(x, _mm256_setzero_ps()), _mm256_set1_ps(h));
            ci = _mm256_min_epi32(_mm256_cvttps_epi32(x), _mm256_set1_epi32(mx));
            f = _mm256_sub_ps(x, _mm256_cvtepi32_ps(ci));
        };
        __m256i vi, vj, vk;
        __m256 wx, wy, wz;
        axis(r.originIndex.x, r.dirIndex.x, sm.hx, sm.mi, vi, wx);
        axis(r.originIndex.y, r.dirIndex.y, sm.hy, sm.mj, vj, wy);
        axis(r.originIndex.z, r.dirIndex.z, sm.hz, sm.mk, vk, wz);
        const __m256i off = _mm256_add_epi32(
            vi, _mm256_add_epi32(_mm256_mullo_epi32(vj, _mm256_set1_epi32(int(sm.sy))),
                                 _mm256_mullo_epi32(vk, _mm256_set1_epi32(int(sm.sz)))));
        // value(): per row, the pair (p[0], p[1]) from one 32-bit gather at a byte address
        // clamped so that the read stays inside the volume, shifted into place.
        const int* base = reinterpret_cast<const int*>(sm.data);
        const __m256i lastWord = _mm256_set1_epi32(int(voxels * sizeof(Elem)) - 4);
        auto pair = [&](__m256i o, __m256& a, __m256& b) {
            const __m256i bytes = sizeof(Elem) == 1 ? o : _mm256_slli_epi32(o, 1);
            const __m256i at = _mm256_min_epi32(bytes, lastWord);
            __m256i w = _mm256_i32gather_epi32(base, at, 1);
            w = _mm256_srlv_epi32(w, _mm256_slli_epi32(_mm256_sub_epi32(bytes, at), 3));
            __m256i lo, hi;
            if constexpr (sizeof(Elem) == 1) {
                lo = _mm256_and_si256(w, _mm256_set1_epi32(0xFF));
                hi = _mm256_and_si256(_mm256_srli_epi32(w, 8), _mm256_set1_epi32(0xFF));
            } else if constexpr (std::is_signed_v<Elem>) {
                lo = _mm256_srai_epi32(_mm256_slli_epi32(w, 16), 16);
                hi = _mm256_srai_epi32(w, 16);
            } else {
                lo = _mm256_and_si256(w, _mm256_set1_epi32(0xFFFF));
                hi = _mm256_srli_epi32(w, 16);
            }
            a = _mm256_cvtepi32_ps(lo);
            b = _mm256_cvtepi32_ps(hi);
        };
        const __m256i dj = _mm256_set1_epi32(int(sm.dj)), dk = _mm256_set1_epi32(int(sm.dk));
        __m256 a0, b0, a1, b1, a2, b2, a3, b3;
        pair(off, a0, b0);
        pair(_mm256_add_epi32(off, dj), a1, b1);
        pair(_mm256_add_epi32(off, dk), a2, b2);
        pair(_mm256_add_epi32(off, _mm256_add_epi32(dk, dj)), a3, b3);
        auto lerp = [](__m256 a, __m256 b, __m256 f) {
            return _mm256_fmadd_ps(f, _mm256_sub_ps(b, a), a);
        };
        const __m256 c0 = lerp(lerp(a0, b0, wx), lerp(a1, b1, wx), wy);
        const __m256 c1 = lerp(lerp(a2, b2, wx), lerp(a3, b3, wx), wy);
        const __m256 sv = _mm256_fmadd_ps(_mm256_set1_ps(sm.slope), lerp(c0, c1, wz),
                                          _mm256_set1_ps(sm.intercept));
        _mm256_store_ps(s, sv);
        // Segment lane l runs from lane l − 1's value (lane 0: `before`); max/min with the
        // previous value second, as std::max/std::min order them.
        const __m256 prev =
            _mm256_blend_ps(_mm256_permutevar8x32_ps(sv, _mm256_setr_epi32(0, 0, 1, 2, 3, 4, 5, 6)),
                            _mm256_set1_ps(before), 1);
        const __m256 hiV = _mm256_max_ps(sv, prev), loV = _mm256_min_ps(sv, prev);
        transparent = unsigned(_mm256_movemask_ps(
            _mm256_or_ps(_mm256_cmp_ps(hiV, _mm256_set1_ps(zeroBelow), _CMP_LE_OQ),
                         _mm256_cmp_ps(loV, _mm256_set1_ps(zeroAbove), _CMP_GE_OQ))));
        _mm256_store_si256(reinterpret_cast<__m256i*>(offset), off);
        _mm256_store_ps(fx, wx);
        _mm256_store_ps(fy, wy);
        _mm256_store_ps(fz, wz);
        if constexpr (kWithCorner) {
            _mm256_store_si256(reinterpret_cast<__m256i*>(ci), vi);
            _mm256_store_si256(reinterpret_cast<__m256i*>(cj), vj);
            _mm256_store_si256(reinterpret_cast<__m256i*>(ck), vk);
        }
    }
};
#endif

template <class View>
[[gnu::always_inline]] inline float sampleAt(const View& v, const RaySegment& r, float t) {
    const glm::vec3 p = r.originIndex + t * r.dirIndex;
    return v.sample(p.x, p.y, p.z);
}

/// World gradient (value/mm) by central differences of the trilinear field at index position p.
template <class View>
[[gnu::always_inline]] inline glm::vec3 gradientAt(const View& v, const glm::vec3& p,
                                                   const glm::mat3& m) {
    const glm::vec3 d(v.sample(p.x + 1.f, p.y, p.z) - v.sample(p.x - 1.f, p.y, p.z),
                      v.sample(p.x, p.y + 1.f, p.z) - v.sample(p.x, p.y - 1.f, p.z),
                      v.sample(p.x, p.y, p.z + 1.f) - v.sample(p.x, p.y, p.z - 1.f));
    return m * d;
}

/// World gradient by forward differences from the known value s0 at p (3 taps instead of 6; the
/// estimate belongs to p + half a voxel, which shading does not notice at clinical zoom).
template <class View>
[[gnu::always_inline]] inline glm::vec3 forwardGradientAt(const View& v, const glm::vec3& p,
                                                          float s0, const glm::mat3& m) {
    const glm::vec3 d(v.sample(p.x + 1.f, p.y, p.z) - s0, v.sample(p.x, p.y + 1.f, p.z) - s0,
                      v.sample(p.x, p.y, p.z + 1.f) - s0);
    return m * (2.f * d);  // m holds 1 / (2·spacing)
}

/// Shading normal facing the eye: the gradient normal, blended toward `fallback` where the gradient
/// is weak (weight |g| / weak, clamped to 1).
[[gnu::always_inline]] inline glm::vec3 shadingNormal(const glm::vec3& g, const glm::vec3& fallback,
                                                      const glm::vec3& toEye, float weak) {
    const float len2 = glm::dot(g, g);
    glm::vec3 n = fallback;
    if (len2 >= weak * weak && len2 > 0.f && len2 < INFINITY) {
        n = g * (-1.f / std::sqrt(len2));  // the common case: a strong, finite gradient
    } else if (len2 > 0.f && len2 < INFINITY) {
        const float len = std::sqrt(len2);
        const float w = len / weak;
        n = w * (-g / len) + (1.f - w) * fallback;
        const float l2 = glm::length(n);
        n = l2 > 1e-6f ? n / l2 : fallback;
    }
    return glm::dot(n, toEye) < 0.f ? -n : n;
}

struct RayResult {
    glm::vec3 radiance{0.f};
    float transmittance = 1.f;
    std::uint64_t samples = 0;
    bool terminated = false;
};

/// Non-empty runs reach the marcher in pieces of at most this many skip cells (kSkipCellVoxels
/// voxels each), so that a ray stops crossing cells soon after it is terminated early; smaller
/// pieces cost more lattice arithmetic and more part-filled sample batches, larger ones more cells
/// crossed in vain (measured with batches: 8 is 3–4 % faster than 4 on bonsai, torso unchanged).
inline constexpr int kRunPieceCells = 8;

/// Calls f(i0, i1) for the lattice index ranges that cover the non-empty intervals of the ray
/// (or the whole ray without skipping), in order and without overlap; f returns false to stop.
template <class F>
inline void forEachActiveRange(const RayCaster& c, const RaySegment& r, const SampleLattice& lat,
                               F&& f) {
    if (!c.options().emptySpaceSkipping) {
        f(std::int64_t(0), lat.last);
        return;
    }
    float t0, t1;
    if (!c.visibleRange(r, t0, t1)) return;
    grid::forEachNonEmptyRun(
        c.majorants(), r.originIndex, r.dirIndex, t0, t1,
        [&](float a, float b) { return f(lat.before(a), lat.after(b)); }, kRunPieceCells);
}

/// Segments longer than one voxel (coarse steps) may see a strongly non-linear value profile
/// (a sharp edge between two samples). Such a segment is split at its midpoint when the midpoint
/// value departs from the linear prediction by more than this fraction of the TF's value range,
/// up to kMaxRefinement times, so that edges land where the trilinear field puts them.
inline constexpr float kLinearityFraction = 0.01f;
inline constexpr int kMaxRefinement = 4;

/// G: the central-difference table type (VoxelGradients or BrickedGradients).
template <class View, class S, class G>
struct DvrMarcher {
    const RayCaster& c;
    const View v;  ///< a copy: stores to the counters below cannot alias its fields
    const CellSampler<View, G::kByIndex> sampler;
    const RaySegment& r;
    /// The shader's per-ray form (ray constants such as halfway vectors hoisted). A shader whose
    /// forRay returns itself is referred to, not copied: the SH shaders hold a shared_ptr and
    /// their lights, and copying them for every ray cost an atomic reference count on a cache
    /// line both render threads write, plus, with point lights, an allocation per ray.
    using RayShaderResult = decltype(std::declval<const S&>().forRay(glm::vec3()));
    using RayShader = std::conditional_t<std::is_reference_v<RayShaderResult>, RayShaderResult,
                                         std::decay_t<RayShaderResult>>;
    const RayShader shader;
    const optics::TfTable& table;
    const G* gradients;  ///< precomputed central differences, or nullptr
    glm::mat3 gradientMatrix;
    bool preint, central;
    float band, weak, voxelsPerMm, linearityTol;
    glm::vec3 toEye;
    float T = 1.f;
    glm::vec3 L{0.f};
    std::uint64_t samples = 0;
    optics::TfTable::SegmentCache cache;       ///< integrals at the last values (each value once)
    bool fused;                                ///< TF without emission: integrals() path
    optics::TfTable::Integrals backIntegrals;  ///< integrals at backValue
    float backValue = NAN;                     ///< back value of the last integrated segment
    typename CellSampler<View, G::kByIndex>::Cell lastCell;  ///< where the last sample was taken
    float lastT = NAN;

    DvrMarcher(const RayCaster& c_, const View& v_, const RaySegment& r_, const S& s_,
               const G* gradients_)
        : c(c_),
          v(v_),
          sampler(v_),
          r(r_),
          shader(s_.forRay(-r_.dirWorld)),
          table(c_.table()),
          gradients(gradients_) {
        preint = c.options().preintegrated;
        fused = !table.hasEmission();
        central = c.options().centralDifferences;
        gradientMatrix = c.gradientMatrix();
        band = kClipFaceBandVoxels * c.stepMm() / c.options().stepVoxels;
        weak = c.weakGradient();
        voxelsPerMm = glm::length(r.dirIndex);
        linearityTol = kLinearityFraction * (table.hi() - table.lo());
        coarse = preint && refinable(c.stepMm() * 1.001f);
        toEye = -r.dirWorld;
    }

#if defined(__AVX2__) && defined(__FMA__)
    using Batch = SampleBatch<View, G::kByIndex>;
    /// Lane l of a batch as the sample just taken (what sample(batch.t[l]) would record).
    [[gnu::always_inline]] float sampleFrom(const Batch& b, int l) {
        ++samples;
        lastCell = b.cell(l);
        lastT = b.t[l];
        return b.s[l];
    }
    /// Whether transparent segments can be passed over without segment(): pre-integrated and
    /// never refined.
    bool skipsTransparent() const { return preint && !coarse; }
#endif

    /// Index-space position at t (fused like SampleBatch).
    [[gnu::always_inline]] glm::vec3 at(float t) const {
        return {fmaF(t, r.dirIndex.x, r.originIndex.x), fmaF(t, r.dirIndex.y, r.originIndex.y),
                fmaF(t, r.dirIndex.z, r.originIndex.z)};
    }

    [[gnu::always_inline]] float sample(float t) {
        ++samples;
        lastCell = sampler.locate(at(t));
        lastT = t;
        return sampler.value(lastCell);
    }

    /// Composites the segment (t0, s0) → (t1, s1); shading at its back end.
    [[gnu::always_inline]] void segment(float t0, float s0, float t1, float s1) {
        if (coarse && refinable(t1 - t0)) {
            refine(t0, s0, t1, s1, 0);
            return;
        }
        if (preint && table.transparentSegment(s0, s1)) return;
        composite(t0, s0, t1, s1);
    }
    bool refinable(float dt) const { return dt * voxelsPerMm > 1.f; }
    /// Whether any segment of this ray can be refinable: no segment is longer than the step
    /// (up to rounding, covered by the 1e-3 margin), so at steps below a voxel the per-segment
    /// test is skipped.
    bool coarse = false;

    /// Pre-integrated segment; the integrals at s1 are kept for the next segment's front.
    [[gnu::always_inline]] optics::TfTable::Segment preintegrated(float s0, float s1) {
        if (!fused) return table.segment(s0, s1, cache);
        if (!(std::abs(s1 - s0) * table.invCellWidth() > optics::TfTable::kPointSampleFraction))
            return table.midpoint(s0, s1);
        const optics::TfTable::Integrals front =
            s0 == backValue ? backIntegrals : table.integrals(s0);
        backIntegrals = table.integrals(s1);
        backValue = s1;
        return table.segment(s0, front, s1, backIntegrals);
    }

    /// A pre-integrated segment longer than a voxel (coarse steps): split at its midpoint while
    /// the value profile departs from linear (kLinearityFraction), up to kMaxRefinement levels.
    /// Kept out of line: at the default step of one voxel or less it never runs.
    [[gnu::noinline]] void refine(float t0, float s0, float t1, float s1, int depth) {
        if (depth < kMaxRefinement && refinable(t1 - t0)) {
            const float sMid = sample(0.5f * (t0 + t1));
            if (std::abs(sMid - 0.5f * (s0 + s1)) > linearityTol &&
                table.segment(std::min({s0, s1, sMid}), std::max({s0, s1, sMid})).meanExtinction >
                    0.f) {
                const float tMid = 0.5f * (t0 + t1);
                refine(t0, s0, tMid, sMid, depth + 1);
                refine(tMid, sMid, t1, s1, depth + 1);
                return;
            }
        }
        composite(t0, s0, t1, s1);
    }

    /// Central difference of the field by six taps, out of line: the table's rare miss.
    [[gnu::noinline]] glm::vec3 sixTapGradient(float t) {
        samples += 6;
        return gradientAt(v, r.originIndex + t * r.dirIndex, gradientMatrix);
    }

    /// One segment of the optical model: opacity from its (pre-integrated) extinction, shading at
    /// its back end — or, for a shader that asks (volumetric scattering with a visibility field,
    /// render/sh_shading.h), at the mean depth of the first scattering inside it: in a dense
    /// segment (bone: σt·Δ of several) the light is scattered within 1/σt of the front, where the
    /// visibility toward the outside is still high, not at the back end deep inside.
    [[gnu::always_inline]] void composite(float t0, float s0, float t1, float s1) {
        const float dt = t1 - t0;
        const optics::TfTable::Segment seg =
            preint ? preintegrated(s0, s1) : table.midpoint(s0, s1);
        const float tau = seg.meanExtinction * dt;
        if (!(tau > 0.f)) return;
        const float alpha = opacity(tau);
        ShadeInput in;
        if constexpr (scattersAtMeanDepth<S>())
            in.position = r.originWorld + (t0 + meanScatterDepth(tau, dt)) * r.dirWorld;
        else
            in.position = r.originWorld + t1 * r.dirWorld;
        in.toEye = toEye;
        in.value = s1;
        in.normal = toEye;
        if constexpr (S::kNeedsNormal) {
            glm::vec3 g;
            if (gradients) {
                // The back end of a segment is (nearly always) the last sample taken.
                const auto cell = t1 == lastT ? lastCell : sampler.locate(at(t1));
                const GradientEntry* q = gradients->corner(cell);
                // A dense table holds every cell; a bricked one may not (then six taps give the
                // same values).
                if (!G::kByIndex || q) {
                    g = gradientAtCell(q, gradients->slope, cell.fx, cell.fy, cell.fz,
                                       gradients->di, gradients->dj, gradients->dk, gradientMatrix);
                    samples += 1;
                } else {
                    g = sixTapGradient(t1);
                }
            } else if (central) {
                g = gradientAt(v, r.originIndex + t1 * r.dirIndex, gradientMatrix);
                samples += 6;
            } else {
                g = forwardGradientAt(v, r.originIndex + t1 * r.dirIndex, s1, gradientMatrix);
                samples += 3;
            }
            const bool cutFace = r.clipEntry && (t1 - r.tNear) < band;
            in.normal = shadingNormal(g, cutFace ? r.entryNormal : toEye, toEye, weak);
        }
        const Scatter sc = shader.scatter(in);
        L += (T * alpha) * (seg.emission + seg.albedo * sc.diffuse + sc.specular);
        T *= 1.f - alpha;
    }
};

/// Front-to-back compositing of the optical model with shader S and the central-difference table
/// `gradients` (may be null).
template <class View, class S, class G>
RayResult marchDvr(const RayCaster& c, const View& v, const RaySegment& r, const S& shader,
                   const G* gradients) {
    RayResult out;
    const SampleLattice lat(r, c.stepMm());
    const float termination =
        c.options().earlyTermination ? c.options().terminationTransmittance : 0.f;
    DvrMarcher<View, S, G> m(c, v, r, shader, gradients);
#if defined(__AVX2__) && defined(__FMA__)
    using Batch = typename DvrMarcher<View, S, G>::Batch;
    const std::size_t voxels = std::size_t(v.nx) * std::size_t(v.ny) * std::size_t(v.nz);
    // Lattice indices must fit the lanes' int32 (steps far below a voxel on long rays do not).
    const bool batched =
        Batch::usable(m.sampler, voxels) && lat.last < std::int64_t(INT32_MAX) - Batch::kLanes;
    const bool skips = m.skipsTransparent();
    const float zeroBelow = c.table().zeroBelow(), zeroAbove = c.table().zeroAbove();
    Batch batches[2];
#endif
    std::int64_t iPrev = -1;
    float sPrev = 0.f, tPrev = 0.f;
    forEachActiveRange(
        c, r, lat, [&](std::int64_t i0, std::int64_t i1) __attribute__((always_inline)) {
            if (iPrev < i0) {
                tPrev = lat.t(i0);
                sPrev = m.sample(tPrev);
                iPrev = i0;
            }
            auto step = [&](std::int64_t i, float t, float s) __attribute__((always_inline)) {
                m.segment(tPrev, sPrev, t, s);
                sPrev = s;
                tPrev = t;
                iPrev = i;
                return m.T < termination;
            };
            std::int64_t i = iPrev + 1;
#if defined(__AVX2__) && defined(__FMA__)
            if constexpr (Batch::kSupported) {
                if (batched) {
                    // Eight samples at a time; lanes past i1 are computed and dropped. The next
                    // batch is taken before this one's segments run (its gathers then overlap
                    // their branches); its lane 0 follows this batch's last lane.
                    Batch* cur = &batches[0];
                    Batch* next = &batches[1];
                    cur->take(i, lat, r, m.sampler, voxels, sPrev, zeroBelow, zeroAbove);
                    for (; i <= i1;) {
                        const int n = int(std::min<std::int64_t>(Batch::kLanes, i1 - i + 1));
                        if (i + Batch::kLanes <= i1)
                            next->take(i + Batch::kLanes, lat, r, m.sampler, voxels,
                                       cur->s[Batch::kLanes - 1], zeroBelow, zeroAbove);
                        const Batch& batch = *cur;
                        int l = 0;
                        if (skips) {
                            // Leading transparent segments change nothing but the last sample.
                            l = std::min(n, __builtin_ctz(~batch.transparent));
                            if (l > 0) {
                                m.sampleFrom(batch, l - 1);
                                m.samples += unsigned(l - 1);
                                sPrev = batch.s[l - 1];
                                tPrev = batch.t[l - 1];
                                i += l;
                                iPrev = i - 1;
                            }
                        }
                        for (; l < n; ++l, ++i)
                            if (step(i, batch.t[l], m.sampleFrom(batch, l))) {
                                out.terminated = true;
                                return false;
                            }
                        std::swap(cur, next);
                    }
                    return true;
                }
            }
#endif
            for (; i <= i1; ++i) {
                const float t = lat.t(i);
                if (step(i, t, m.sample(t))) {
                    out.terminated = true;
                    return false;
                }
            }
            return true;
        });
    out.radiance = m.L;
    out.transmittance = m.T;
    out.samples = m.samples;
    return out;
}

/// Maximum (kMax) or minimum intensity along the ray; NaN samples are ignored. Returns false when
/// no finite sample was seen.
template <bool kMax, class View>
bool marchExtremum(const RayCaster& c, const View& v, const RaySegment& r, float& result,
                   std::uint64_t& samples) {
    const SampleLattice lat(r, c.stepMm());
    float m = kMax ? -INFINITY : INFINITY;
    bool any = false;
    // Local copies, so that the compiler keeps them in registers across the sample loop.
    const View view = v;
    std::uint64_t taken = 0;
    auto visit = [&](std::int64_t i0, std::int64_t i1) {
        for (std::int64_t i = i0; i <= i1; ++i) {
            const float s = sampleAt(view, r, lat.t(i));
            ++taken;
            if (kMax ? s > m : s < m) m = s, any = true;
        }
    };
    if (!c.options().emptySpaceSkipping) {
        visit(0, lat.last);
    } else {
        // Skip cells that cannot beat the current extremum (samples inside a cell are bounded by
        // its value range; a skipped sample can therefore not change the result).
        const grid::BrickMajorants& cells = c.majorants();
        std::int64_t done = -1;
        grid::forEachCell(cells, r.originIndex, r.dirIndex, r.tNear, r.tFar,
                          [&](float t0, float t1, std::size_t cell) {
                              const std::array<float, 2>& range = cells.valueRange(cell);
                              if (any && (kMax ? range[1] <= m : range[0] >= m)) return true;
                              const std::int64_t i0 = std::max(lat.before(t0), done + 1);
                              const std::int64_t i1 = lat.after(t1);
                              if (i1 < i0) return true;
                              visit(i0, i1);
                              done = i1;
                              return true;
                          });
    }
    samples += taken;
    result = m;
    return any;
}

struct IsoHit {
    float t = 0.f;
    glm::vec3 normal{0.f};  ///< facing the eye
};

/// First crossing of the isovalue (Ritschel's DIR): lattice search, then bisection on the
/// trilinear field. A ray that enters through a clip plane inside the object hits the cap.
template <class View>
bool marchIso(const RayCaster& c, const View& v, const RaySegment& r, IsoHit& hit,
              std::uint64_t& samples) {
    constexpr int kBisections = 12;  // 2^-12 of a step: far below a voxel
    const float iso = c.isoValue();
    const SampleLattice lat(r, c.stepMm());
    const glm::vec3 toEye = -r.dirWorld;
    // A ray that enters through a clip plane inside the object hits the cap (checked before the
    // skipping, because a brick entirely inside the object holds no crossing).
    const float f0 = sampleAt(v, r, r.tNear) - iso;
    ++samples;
    // The volume's own boundary closes the surface too (a ray from outside that enters above the
    // isovalue sees that face); a camera inside the object looks for the way out instead.
    if (f0 >= 0.f && (r.clipEntry || r.tNear > 0.f)) {
        hit.t = r.tNear;
        hit.normal = r.clipEntry ? r.entryNormal : -r.dirWorld;
        return true;
    }
    std::int64_t iPrev = -1;
    float fPrev = 0.f, tPrev = 0.f;
    bool found = false;
    forEachActiveRange(c, r, lat, [&](std::int64_t i0, std::int64_t i1) {
        if (iPrev < i0) {
            tPrev = lat.t(i0);
            fPrev = sampleAt(v, r, tPrev) - iso;
            ++samples;
            iPrev = i0;
        }
        for (std::int64_t i = iPrev + 1; i <= i1; ++i) {
            const float t = lat.t(i);
            const float f = sampleAt(v, r, t) - iso;
            ++samples;
            if ((f >= 0.f) != (fPrev >= 0.f)) {
                float a = tPrev, b = t;
                const bool risingAtB = f >= 0.f;
                for (int k = 0; k < kBisections; ++k) {
                    const float m = 0.5f * (a + b);
                    ((sampleAt(v, r, m) - iso >= 0.f) == risingAtB ? b : a) = m;
                }
                samples += kBisections;
                hit.t = 0.5f * (a + b);
                const glm::vec3 p = r.originIndex + hit.t * r.dirIndex;
                const glm::vec3 g = gradientAt(v, p, c.gradientMatrix());
                samples += 6;
                hit.normal = shadingNormal(g, toEye, toEye, 0.f);
                found = true;
                return false;
            }
            fPrev = f;
            tPrev = t;
            iPrev = i;
        }
        return true;
    });
    return found;
}

inline void writeMiss(float* px, const glm::vec3& bg) {
    px[0] = bg.r, px[1] = bg.g, px[2] = bg.b, px[3] = 0.f;
}

/// Guards the "never NaN pixels" promise at the last possible point.
inline float finiteOr0(float v) { return std::isfinite(v) ? v : 0.f; }

/// The DVR shading model of any shader (ShadingModel per tile, marchDvr per pixel): what the
/// built-in modes and later methods (SH visibility, ...) plug into RayCaster::render.
template <class Shader>
class DvrModel final : public ShadingModel {
  public:
    /// `footprint`: the pixels that can see a non-empty cell; when the tiles are rendered with its
    /// camera, the others get the background without a ray.
    DvrModel(std::string name, Shader shader, PixelFootprint footprint)
        : name_(std::move(name)), shader_(std::move(shader)), footprint_(std::move(footprint)) {}
    std::string name() const override { return name_; }
    void renderTile(const RayCaster& c, const Camera& cam, int x0, int y0, int x1, int y1,
                    core::ImageRGBA& film, RenderStats& stats) const override {
        const glm::vec3 bg = c.options().background;
        const bool footprint = footprint_.builtFor(cam);
        auto tile = [&](const auto& view, const auto* gradients) {
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x) {
                    float* px = film.at(x, y);
                    if (footprint && !footprint_.covers(x, y)) {
                        writeMiss(px, bg);  // what marchDvr returns without a non-empty cell
                        continue;
                    }
                    const RaySegment r = c.setupRay(cam, x, y);
                    if (!r.hit()) {
                        writeMiss(px, bg);
                        continue;
                    }
                    const detail::RayResult res = detail::marchDvr(c, view, r, shader_, gradients);
                    const float T = res.transmittance;
                    for (int k = 0; k < 3; ++k) px[k] = finiteOr0(res.radiance[k] + T * bg[k]);
                    px[3] = finiteOr0(1.f - T);
                    ++stats.rays;
                    stats.samples += res.samples;
                    stats.terminatedEarly += res.terminated ? 1 : 0;
                }
        };
        c.volume().visit([&](const auto& view) {
            if constexpr (Shader::kNeedsNormal) {
                if (const BrickedGradients* b = c.brickedGradients())
                    tile(view, b);
                else
                    tile(view, c.voxelGradients());
            } else {
                tile(view, static_cast<const VoxelGradients*>(nullptr));
            }
        });
    }

  private:
    std::string name_;
    Shader shader_;
    PixelFootprint footprint_;
};

}  // namespace voxlight::render::detail
