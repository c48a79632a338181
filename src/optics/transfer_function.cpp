// SPDX-License-Identifier: MIT
#include "optics/transfer_function.h"

#if defined(__AVX2__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <ostream>
#include <sstream>

#include "core/error.h"

namespace voxlight::optics {

std::ostream& operator<<(std::ostream& os, const TfPoint& p) {
    os << "{value " << p.value << ", color (" << p.color.r << ", " << p.color.g << ", " << p.color.b
       << "), extinction " << p.extinction << "/mm, specular (" << p.specular.r << ", "
       << p.specular.g << ", " << p.specular.b << "), roughness " << p.roughness;
    if (!std::isnan(p.phaseG)) os << ", phase g " << p.phaseG;
    return os << "}";
}

std::ostream& operator<<(std::ostream& os, const TransferFunction& tf) {
    os << "TransferFunction '" << tf.name() << "' window L" << tf.window().level << " W"
       << tf.window().width << " [";
    for (const auto& p : tf.points()) os << p << " ";
    return os << "]";
}

namespace {
bool finite3(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
}  // namespace

TransferFunction::TransferFunction(std::vector<TfPoint> points, Window window, std::string name)
    : points_(std::move(points)), window_(window), name_(std::move(name)) {
    const std::string src = "transfer function '" + name_ + "'";
    if (points_.empty())
        throw InputError(src, "points", "is empty", "give at least one control point");
    for (std::size_t i = 0; i < points_.size(); ++i) {
        const TfPoint& p = points_[i];
        const std::string field = "points[" + std::to_string(i) + "]";
        std::ostringstream os;
        os << p;
        if (!std::isfinite(p.value)) throw InputError(src, field + ".value", "is not finite");
        if (i > 0 && !(p.value > points_[i - 1].value))
            throw InputError(src, field + ".value",
                             "must be strictly increasing; got " + std::to_string(p.value) +
                                 " after " + std::to_string(points_[i - 1].value),
                             "sort the points by value");
        if (!finite3(p.color) || glm::any(glm::lessThan(p.color, glm::vec3(0.f))) ||
            glm::any(glm::greaterThan(p.color, glm::vec3(1.f))))
            throw InputError(src, field + ".color", "must be in [0, 1], got " + os.str());
        if (!std::isfinite(p.extinction) || p.extinction < 0.f)
            throw InputError(src, field + ".extinction",
                             "must be finite and >= 0, got " + os.str());
        if (!finite3(p.emission) || glm::any(glm::lessThan(p.emission, glm::vec3(0.f))))
            throw InputError(src, field + ".emission", "must be finite and >= 0");
        if (!finite3(p.specular) || glm::any(glm::lessThan(p.specular, glm::vec3(0.f))) ||
            glm::any(glm::greaterThan(p.specular, glm::vec3(1.f))))
            throw InputError(src, field + ".specular", "must be in [0, 1], got " + os.str());
        if (!(p.roughness > 0.f && p.roughness <= 1.f))
            throw InputError(src, field + ".roughness", "must be in (0, 1], got " + os.str());
        if (std::isnan(p.phaseG) != std::isnan(points_.front().phaseG))
            throw InputError(src, field + ".phase_g", "is given on some points but not on others",
                             "give phase_g on every point or on none");
        if (!std::isnan(p.phaseG) && !(std::abs(p.phaseG) < 1.f))
            throw InputError(src, field + ".phase_g", "must lie strictly between -1 and 1");
    }
    if (!(window_.width > 0.f) || !std::isfinite(window_.width) || !std::isfinite(window_.level))
        throw InputError(src, "window", "width must be finite and > 0, level finite");
}

TfSample TransferFunction::eval(float value) const {
    const auto toSample = [](const TfPoint& p) {
        return TfSample{p.extinction, p.color, p.emission};
    };
    if (!(value > points_.front().value)) return toSample(points_.front());  // NaN → low end
    if (value >= points_.back().value) return toSample(points_.back());
    const auto it = std::upper_bound(points_.begin(), points_.end(), value,
                                     [](float v, const TfPoint& p) { return v < p.value; });
    const TfPoint& b = *it;
    const TfPoint& a = *(it - 1);
    const float f = (value - a.value) / (b.value - a.value);
    TfSample s;
    s.extinction = a.extinction + f * (b.extinction - a.extinction);
    s.albedo = a.color + f * (b.color - a.color);
    s.emission = a.emission + f * (b.emission - a.emission);
    return s;
}

TfSurface TransferFunction::evalSurface(float value) const {
    const auto toSurface = [](const TfPoint& p) {
        return TfSurface{p.specular, p.roughness, p.phaseG};
    };
    if (!(value > points_.front().value)) return toSurface(points_.front());  // NaN → low end
    if (value >= points_.back().value) return toSurface(points_.back());
    const auto it = std::upper_bound(points_.begin(), points_.end(), value,
                                     [](float v, const TfPoint& p) { return v < p.value; });
    const TfPoint& b = *it;
    const TfPoint& a = *(it - 1);
    const float f = (value - a.value) / (b.value - a.value);
    TfSurface s;
    s.specular = a.specular + f * (b.specular - a.specular);
    s.roughness = a.roughness + f * (b.roughness - a.roughness);
    s.phaseG = a.phaseG + f * (b.phaseG - a.phaseG);
    return s;
}

float TransferFunction::maxExtinction(float lo, float hi) const {
    if (lo > hi) std::swap(lo, hi);
    float m = std::max(eval(lo).extinction, eval(hi).extinction);
    for (const auto& p : points_)
        if (p.value > lo && p.value < hi) m = std::max(m, p.extinction);
    return m;
}

float TransferFunction::maxExtinction() const {
    float m = 0.f;
    for (const auto& p : points_) m = std::max(m, p.extinction);
    return m;
}

TransferFunction TransferFunction::scaledExtinction(float scale) const {
    VL_CHECK(scale >= 0.f && std::isfinite(scale));
    TransferFunction t = *this;
    for (auto& p : t.points_) p.extinction *= scale;
    return t;
}

TransferFunction TransferFunction::withWindow(const Window& w) const {
    if (!(w.width > 0.f) || !std::isfinite(w.width) || !std::isfinite(w.level))
        throw InputError("transfer function '" + name_ + "'", "window",
                         "width must be finite and > 0, level finite",
                         "e.g. \"window\": {\"level\": 400, \"width\": 1500}");
    TransferFunction t = *this;
    const float k = w.width / window_.width;
    for (auto& p : t.points_) p.value = w.level + (p.value - window_.level) * k;
    t.window_ = w;
    return t;
}

float TransferFunction::surfaceValue() const {
    // A tenth of the maximum: where a surface TF's ramp starts to become visible, which is where
    // clinicians put a threshold (e.g. ≈ 260 HU for ct-bone).
    const float half = 0.1f * maxExtinction();
    if (!(half > 0.f)) return window_.level;
    if (points_.front().extinction >= half) return points_.front().value;
    for (std::size_t i = 1; i < points_.size(); ++i) {
        const TfPoint &a = points_[i - 1], &b = points_[i];
        if (b.extinction >= half)
            return a.value +
                   (half - a.extinction) / (b.extinction - a.extinction) * (b.value - a.value);
    }
    return points_.back().value;
}

// ---------------------------------------------------------------------------------------------
TfTable::TfTable(const TransferFunction& tf) {
    lo_ = tf.points().front().value;
    hi_ = tf.points().back().value;
    if (!(hi_ > lo_)) hi_ = lo_ + 1.f;  // single point: constant TF; any width works
    cell_ = (double(hi_) - double(lo_)) / kTableCells;
    invCell_ = float(1.0 / cell_);
    invCellD_ = 1.0 / cell_;
    const std::size_t n = kTableCells + 1;
    nodes_.resize(n);
    surface_.resize(n);
    hasPhaseG_ = tf.hasPhaseG();
    sigma_.resize(n);
    weighted_.resize(n);
    cumSigma_.resize(n);
    cumWeighted_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        const TfSample s = tf.eval(float(double(lo_) + cell_ * double(i)));
        nodes_[i] = {s.extinction, s.albedo, s.emission};
        const TfSurface u = tf.evalSurface(float(double(lo_) + cell_ * double(i)));
        surface_[i] = {u.specular, u.roughness, u.phaseG};
        sigma_[i] = s.extinction;
        for (int c = 0; c < 3; ++c) {
            weighted_[i][c] = s.extinction * s.albedo[c];
            weighted_[i][3 + c] = s.extinction * (1.f - s.albedo[c]) * s.emission[c];
            emissive_ |= weighted_[i][3 + c] > 0.f;
        }
    }
    // Cumulative integrals of the linearly interpolated table (the trapezoid rule is exact).
    cumSigma_[0] = 0.0;
    cumWeighted_[0].fill(0.0);
    for (std::size_t i = 1; i < n; ++i) {
        cumSigma_[i] = cumSigma_[i - 1] + 0.5 * cell_ * (double(sigma_[i - 1]) + sigma_[i]);
        for (int c = 0; c < 6; ++c)
            cumWeighted_[i][c] = cumWeighted_[i - 1][c] +
                                 0.5 * cell_ * (double(weighted_[i - 1][c]) + weighted_[i][c]);
    }
    fused_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        fused_[i].cum[0] = cumSigma_[i];
        fused_[i].f[0] = sigma_[i];
        for (int c = 0; c < 3; ++c) {
            fused_[i].cum[1 + c] = cumWeighted_[i][c];
            fused_[i].f[1 + c] = weighted_[i][c];
        }
    }
    {
        const int rows = std::bit_width(n);
        sigmaRunMax_.assign(std::size_t(rows) * n, 0.f);
        sigmaRunMin_.assign(std::size_t(rows) * n, 0.f);
        std::copy(sigma_.begin(), sigma_.end(), sigmaRunMax_.begin());
        std::copy(sigma_.begin(), sigma_.end(), sigmaRunMin_.begin());
        for (int j = 1; j < rows; ++j) {
            const std::size_t half = std::size_t(1) << (j - 1);
            const float* prev = sigmaRunMax_.data() + std::size_t(j - 1) * n;
            float* row = sigmaRunMax_.data() + std::size_t(j) * n;
            const float* prevMin = sigmaRunMin_.data() + std::size_t(j - 1) * n;
            float* rowMin = sigmaRunMin_.data() + std::size_t(j) * n;
            for (std::size_t i = 0; i < n; ++i) {
                row[i] = i + half < n ? std::max(prev[i], prev[i + half]) : prev[i];
                rowMin[i] = i + half < n ? std::min(prevMin[i], prevMin[i + half]) : prevMin[i];
            }
        }
    }
    sigmaNodes_.resize(kTableCells);
    for (std::size_t i = 0; i < std::size_t(kTableCells); ++i)
        sigmaNodes_[i] = {cumSigma_[i], sigma_[i], sigma_[i + 1]};
    // Transparent ends, for the O(1) rejection of segments that see no extinction at all.
    std::size_t first = 0, last = n - 1;
    while (first < n && sigma_[first] <= 0.f) ++first;
    while (last > 0 && sigma_[last] <= 0.f) --last;
    if (first == n) {  // transparent everywhere
        zeroBelow_ = INFINITY;
        zeroAbove_ = -INFINITY;
    } else {
        zeroBelow_ = first == 0 ? -INFINITY : float(double(lo_) + cell_ * double(first - 1));
        zeroAbove_ = last == n - 1 ? INFINITY : float(double(lo_) + cell_ * double(last + 1));
    }
}

namespace {
#if defined(__AVX2__)
/// Four lanes of sigmaIntegral (TfTable::sigmaIntegrals): the in-range formula at a clamped cell
/// and the linear extensions past either end, selected per lane.
struct SigmaIntegral4 {
    __m256d lo, inv, width, half, cells, cumLo, fLo, cumHi, fHi;
    const double* nodes;  // SigmaNode array as doubles: {cum, (f, fNext)} per node
    __m256d operator()(__m128 s) const {
        const __m256d zero = _mm256_setzero_pd();
        const __m256d u = _mm256_mul_pd(_mm256_sub_pd(_mm256_cvtps_pd(s), lo), inv);
        const __m256d inside =
            _mm256_and_pd(_mm256_cmp_pd(u, zero, _CMP_GT_OQ), _mm256_cmp_pd(u, cells, _CMP_LT_OQ));
        const __m256d uc = _mm256_and_pd(u, inside);  // 0 outside: reads cell 0, discarded
        const __m128i cell = _mm256_cvttpd_epi32(uc);
        const __m256d x = _mm256_mul_pd(_mm256_sub_pd(uc, _mm256_cvtepi32_pd(cell)), width);
        // Each lane's 16-byte node in one load, transposed: fewer and cheaper than two gathers
        // (AMD Zen's gathers are microcoded; 4-lane gathers are no faster on Intel either).
        alignas(16) std::int32_t c[4];
        _mm_store_si128(reinterpret_cast<__m128i*>(c), cell);
        const __m256d even =
            _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_loadu_pd(nodes + 2 * c[0])),
                                 _mm_loadu_pd(nodes + 2 * c[2]), 1);
        const __m256d odd =
            _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_loadu_pd(nodes + 2 * c[1])),
                                 _mm_loadu_pd(nodes + 2 * c[3]), 1);
        const __m256d cum = _mm256_unpacklo_pd(even, odd);  // node cum of lanes 0, 1, 2, 3
        const __m256 pair = _mm256_castpd_ps(_mm256_unpackhi_pd(even, odd));  // (f, fNext)
        const __m256 split =
            _mm256_permutevar8x32_ps(pair, _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7));
        const __m256d f = _mm256_cvtps_pd(_mm256_castps256_ps128(split));
        const __m256d fNext = _mm256_cvtps_pd(_mm256_extractf128_ps(split, 1));
        const __m256d in = _mm256_add_pd(
            _mm256_add_pd(cum, _mm256_mul_pd(f, x)),
            _mm256_mul_pd(_mm256_mul_pd(_mm256_sub_pd(fNext, f), _mm256_mul_pd(x, x)), half));
        const __m256d above =
            _mm256_add_pd(cumHi, _mm256_mul_pd(fHi, _mm256_mul_pd(_mm256_sub_pd(u, cells), width)));
        const __m256d below = _mm256_add_pd(cumLo, _mm256_mul_pd(fLo, _mm256_mul_pd(u, width)));
        const __m256d outside = _mm256_blendv_pd(below, above, _mm256_cmp_pd(u, zero, _CMP_GT_OQ));
        return _mm256_blendv_pd(outside, in, inside);
    }
};
#endif
}  // namespace

void TfTable::sigmaIntegrals(const float* s, std::size_t n, double* out) const {
#if defined(__AVX2__)
    static_assert(sizeof(SigmaNode) == 2 * sizeof(double));
    const SigmaIntegral4 lanes{_mm256_set1_pd(double(lo_)),
                               _mm256_set1_pd(invCellD_),
                               _mm256_set1_pd(cell_),
                               _mm256_set1_pd(0.5 * invCellD_),
                               _mm256_set1_pd(double(kTableCells)),
                               _mm256_set1_pd(fused_.front().cum[0]),
                               _mm256_set1_pd(double(fused_.front().f[0])),
                               _mm256_set1_pd(fused_.back().cum[0]),
                               _mm256_set1_pd(double(fused_.back().f[0])),
                               reinterpret_cast<const double*>(sigmaNodes_.data())};
    std::size_t i = 0;
    for (; i + 4 <= n; i += 4) _mm256_storeu_pd(out + i, lanes(_mm_loadu_ps(s + i)));
    if (i < n) {  // the tail through the same lanes
        alignas(16) float in[4] = {0.f, 0.f, 0.f, 0.f};
        alignas(32) double res[4];
        std::copy(s + i, s + n, in);
        _mm256_store_pd(res, lanes(_mm_load_ps(in)));
        std::copy(res, res + (n - i), out + i);
    }
#else
    for (std::size_t i = 0; i < n; ++i) out[i] = sigmaIntegral(s[i]);
#endif
}

void TfTable::meanExtinctions(const float* s, const double* integrals, std::size_t n,
                              float* out) const {
#if defined(__AVX2__)
    // meanExtinction's two cases for four segments at a time, selected per lane (a point-sampled
    // segment's quotient may divide by 0: discarded).
    const __m128 lo = _mm_set1_ps(lo_), invCell = _mm_set1_ps(invCell_),
                 cells = _mm_set1_ps(float(kTableCells)), zero = _mm_setzero_ps(),
                 pointFraction = _mm_set1_ps(kPointSampleFraction),
                 absMask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff)),
                 below = _mm_set1_ps(zeroBelow_), above = _mm_set1_ps(zeroAbove_);
    const __m128i lastCell = _mm_set1_epi32(kTableCells - 1);
    const float* sigma = sigma_.data();
    auto four = [&](__m128 sf4, __m128 sb4, __m256d iF, __m256d iB) {
        // extinction(½ (sf + sb)) as position() clamps it.
        __m128 u = _mm_mul_ps(_mm_sub_ps(_mm_mul_ps(_mm_set1_ps(0.5f), _mm_add_ps(sf4, sb4)), lo),
                              invCell);
        u = _mm_min_ps(_mm_max_ps(u, zero), cells);
        const __m128i c4 = _mm_min_epi32(_mm_cvttps_epi32(u), lastCell);
        const __m128 fr = _mm_sub_ps(u, _mm_cvtepi32_ps(c4));
        // σt at cells c and c + 1 of each lane: one 8-byte load per lane instead of two gathers.
        alignas(16) std::int32_t c[4];
        _mm_store_si128(reinterpret_cast<__m128i*>(c), c4);
        auto adjacent = [&](int lane) {
            return _mm_castsi128_ps(
                _mm_loadl_epi64(reinterpret_cast<const __m128i*>(sigma + c[lane])));
        };
        const __m128 p01 = _mm_movelh_ps(adjacent(0), adjacent(1));  // a0 b0 a1 b1
        const __m128 p23 = _mm_movelh_ps(adjacent(2), adjacent(3));  // a2 b2 a3 b3
        const __m128 a = _mm_shuffle_ps(p01, p23, _MM_SHUFFLE(2, 0, 2, 0));
        const __m128 b = _mm_shuffle_ps(p01, p23, _MM_SHUFFLE(3, 1, 3, 1));
        const __m128 mid = _mm_add_ps(a, _mm_mul_ps(fr, _mm_sub_ps(b, a)));
        const __m128 point =
            _mm_cmp_ps(_mm_mul_ps(_mm_and_ps(_mm_sub_ps(sb4, sf4), absMask), invCell),
                       pointFraction, _CMP_NGT_UQ);  // !(|Δ|/cell > fraction)
        const __m256d q = _mm256_div_pd(_mm256_sub_pd(iB, iF),
                                        _mm256_sub_pd(_mm256_cvtps_pd(sb4), _mm256_cvtps_pd(sf4)));
        const __m256d qPos = _mm256_and_pd(q, _mm256_cmp_pd(q, _mm256_setzero_pd(), _CMP_GT_OQ));
        const __m128 quotient = _mm256_cvtpd_ps(qPos);
        // 0 where both ends lie in one transparent tail (as segment() rejects them; the
        // integrals there are equal anyway, but a point sample at a tail's end may round in).
        const __m128 tail = _mm_or_ps(_mm_cmp_ps(_mm_max_ps(sf4, sb4), below, _CMP_LE_OQ),
                                      _mm_cmp_ps(_mm_min_ps(sf4, sb4), above, _CMP_GE_OQ));
        return _mm_andnot_ps(tail, _mm_blendv_ps(quotient, mid, point));
    };
    std::size_t e = 0;
    for (; e + 4 <= n; e += 4)
        _mm_storeu_ps(out + e,
                      four(_mm_loadu_ps(s + e), _mm_loadu_ps(s + e + 1),
                           _mm256_loadu_pd(integrals + e), _mm256_loadu_pd(integrals + e + 1)));
    if (e < n) {
        alignas(16) float f4[4] = {0.f, 0.f, 0.f, 0.f}, b4[4] = {0.f, 0.f, 0.f, 0.f};
        alignas(32) double iF[4] = {0.0, 0.0, 0.0, 0.0}, iB[4] = {0.0, 0.0, 0.0, 0.0};
        alignas(16) float res[4];
        for (std::size_t k = 0; e + k < n; ++k) {
            f4[k] = s[e + k];
            b4[k] = s[e + k + 1];
            iF[k] = integrals[e + k];
            iB[k] = integrals[e + k + 1];
        }
        _mm_store_ps(
            res, four(_mm_load_ps(f4), _mm_load_ps(b4), _mm256_load_pd(iF), _mm256_load_pd(iB)));
        std::copy(res, res + (n - e), out + e);
    }
#else
    for (std::size_t e = 0; e < n; ++e)
        out[e] = transparentSegment(s[e], s[e + 1])
                     ? 0.f
                     : meanExtinction(s[e], integrals[e], s[e + 1], integrals[e + 1]);
#endif
}

TfTable::Nodes TfTable::nodes() const {
    Nodes n;
    n.lo = lo_;
    n.hi = hi_;
    n.cell = cell_;
    n.sigma = sigma_;
    n.weighted = weighted_;
    n.cumSigma = cumSigma_;
    n.cumWeighted = cumWeighted_;
    for (const Node& node : nodes_) {
        n.albedo.push_back(node.albedo);
        n.emission.push_back(node.emission);
    }
    return n;
}

double TfTable::cumulativeSigma(double value, int& cell, double& x) const {
    const double u = (value - double(lo_)) * invCellD_;
    if (!(u > 0.0)) {  // below the range (or NaN): constant extension of the first node
        cell = -1;
        x = std::isnan(u) ? 0.0 : u * cell_;
        return double(sigma_.front()) * x;
    }
    if (u >= kTableCells) {
        cell = kTableCells;
        x = (u - kTableCells) * cell_;
        return cumSigma_.back() + double(sigma_.back()) * x;
    }
    cell = int(u);
    x = (u - cell) * cell_;
    const double a = sigma_[std::size_t(cell)], b = sigma_[std::size_t(cell) + 1];
    // ∫_0^x (a + (b − a) t / h) dt = a·x + (b − a)·x² / (2h): exact inside the linear cell.
    return cumSigma_[std::size_t(cell)] + a * x + (b - a) * x * x * (0.5 * invCellD_);
}

void TfTable::cumulativeWeighted(double value, int cell, double x, double out[6]) const {
    // Without emission anywhere the last three integrals are 0 and not evaluated.
    const int channels = emissive_ ? 6 : 3;
    for (int c = channels; c < 6; ++c) out[c] = 0.0;
    if (cell < 0) {
        for (int c = 0; c < channels; ++c) out[c] = double(weighted_.front()[c]) * x;
        return;
    }
    if (cell >= kTableCells) {
        for (int c = 0; c < channels; ++c)
            out[c] = cumWeighted_.back()[c] + double(weighted_.back()[c]) * x;
        return;
    }
    const auto& a = weighted_[std::size_t(cell)];
    const auto& b = weighted_[std::size_t(cell) + 1];
    const auto& base = cumWeighted_[std::size_t(cell)];
    const double q = x * x * (0.5 * invCellD_);
    for (int c = 0; c < channels; ++c) out[c] = base[c] + a[c] * x + (double(b[c]) - a[c]) * q;
}

TfTable::Segment TfTable::midpoint(float sf, float sb) const {
    const TfSample s = lookup(0.5f * (sf + sb));
    Segment g;
    g.meanExtinction = s.extinction;
    g.albedo = s.albedo;
    g.emission = (glm::vec3(1.f) - s.albedo) * s.emission;
    return g;
}

TfTable::Cumulative& TfTable::cumulative(float value, SegmentCache& cache,
                                         const Cumulative* other) const {
    for (Cumulative& c : cache.slot)
        if (c.value == value) return c;  // NaN never equals: recomputed below
    Cumulative& c = &cache.slot[0] == other ? cache.slot[1] : cache.slot[0];
    c.value = value;
    c.haveWeighted = false;
    c.sigma = cumulativeSigma(value, c.cell, c.x);
    return c;
}

void TfTable::ensureWeighted(Cumulative& c) const {
    if (c.haveWeighted) return;
    cumulativeWeighted(double(c.value), c.cell, c.x, c.weighted);
    c.haveWeighted = true;
}

TfTable::Segment TfTable::segmentSlow(float sf, float sb, SegmentCache* cache) const {
    if (!(std::abs(sb - sf) * invCell_ > kPointSampleFraction)) return midpoint(sf, sb);
    Cumulative local[2];
    Cumulative* a;
    Cumulative* b;
    if (cache) {
        a = &cumulative(sf, *cache, nullptr);
        b = &cumulative(sb, *cache, a);
    } else {
        a = &local[0], b = &local[1];
        a->value = sf, b->value = sb;
        a->sigma = cumulativeSigma(sf, a->cell, a->x);
        b->sigma = cumulativeSigma(sb, b->cell, b->x);
    }
    const double ia = a->sigma, ib = b->sigma;
    const double inv = 1.0 / (double(sb) - double(sf));
    const double sigma = (ib - ia) * inv;
    Segment g;
    if (!(sigma > 0.0)) return g;
    g.meanExtinction = float(sigma);
    ensureWeighted(*a);
    ensureWeighted(*b);
    const double* wa = a->weighted;
    const double* wb = b->weighted;
    const double w = 1.0 / (ib - ia);
    for (int c = 0; c < 3; ++c) {
        g.albedo[c] = float(std::clamp((wb[c] - wa[c]) * w, 0.0, 1.0));
        g.emission[c] = float(std::max((wb[3 + c] - wa[3 + c]) * w, 0.0));
    }
    return g;
}

ValueInterval extinctionChange(const TfTable::ExtinctionProfile& before,
                               const TfTable::ExtinctionProfile& after) {
    if (before.lo != after.lo || before.hi != after.hi || before.sigma.size() != after.sigma.size())
        return {-INFINITY, INFINITY};
    const std::size_t n = after.sigma.size();
    std::size_t first = n, last = 0;
    for (std::size_t i = 0; i < n; ++i)
        if (std::bit_cast<std::uint32_t>(before.sigma[i]) !=
            std::bit_cast<std::uint32_t>(after.sigma[i])) {
            first = std::min(first, i);
            last = i;
        }
    if (first == n) return {};
    const double cell = (double(after.hi) - double(after.lo)) / double(n - 1);
    ValueInterval v;
    v.lo = first == 0 ? -INFINITY : float(double(after.lo) + cell * (double(first) - 2.0));
    v.hi = last == n - 1 ? INFINITY : float(double(after.lo) + cell * (double(last) + 2.0));
    return v;
}

}  // namespace voxlight::optics
