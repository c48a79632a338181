// SPDX-License-Identifier: MIT
#pragma once
// Transfer functions: physical value (HU for CT) → optical properties, following the one optical
// model of ARCHITECTURE.md §1:
//   σt(s)        extinction, 1/mm (≥ 0); a step of length Δ mm has opacity α = 1 − exp(−σt·Δ)
//   a(s)         single-scattering albedo, linear RGB in [0, 1] (the "colour" of a tissue)
//   e(s)         emitted radiance, linear RGB (≥ 0), weighted by (1 − a) in the source term
// and, for the path tracer's surface-like (hybrid) scattering only (pathtrace/brdf.h):
//   specular(s)  the BRDF's specular colour F0 (Schlick), linear RGB in [0, 1]; default 0
//   roughness(s) the BRDF's roughness r ∈ (0, 1] (GGX α = r²); default 1 (matte)
//   g(s)         Henyey–Greenstein asymmetry ∈ (−1, 1) of the phase function; optional as a whole:
//                a TF gives it on every point or on none, and without it the path tracer uses
//                its method parameter phase_g (hasPhaseG())
// Every property is piecewise linear between control points (strictly increasing value) and
// constant beyond the first and last point. The surface channels never change σt, a or e, so
// every method but the path tracer's hybrid/BRDF scattering ignores them.
//
// Window/level remaps the value axis: a TF is authored for a reference window [level0 ± width0/2]
// and `withWindow(level, width)` stretches/shifts every control point so that the reference window
// lands on the new one (extinctions and colours are unchanged). MIP/MinIP use the window as their
// grey ramp.
//
// Fast evaluation (TfTable): the TF is resampled on kTableCells equal cells over
// [firstPoint, lastPoint] and evaluated by linear interpolation. Pre-integration (Engel, Kraus &
// Ertl 2001, "High-quality pre-integrated volume rendering using hardware-accelerated pixel
// shading"; here in the "no self-attenuation of colour inside a segment" variant, which is exact
// for opacity): along a segment of length Δ whose value varies linearly from sf to sb,
//   τ = Δ · mean_{[sf,sb]} σt            (exact optical depth under linear interpolation)
//   A = mean(σt·a) / mean(σt)             (extinction-weighted albedo)
//   E = mean(σt·(1−a)·e) / mean(σt)       (extinction-weighted emission term)
// and the means come from cumulative integrals (double precision, exact quadratic inside a cell),
// so a TF that steps sharply between two samples still contributes its exact share. Because the
// tables are independent of Δ, partial segments (clip planes, jittered starts) are exact too.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <glm/glm.hpp>
#include <iosfwd>
#include <string>
#include <utility>
#include <vector>

namespace voxlight::optics {

/// TfPoint::phaseG when the point (and so the TF) carries no phase asymmetry.
inline constexpr float kNoPhaseG = NAN;

struct TfPoint {
    float value = 0.f;         ///< physical value (HU for CT)
    glm::vec3 color{1.f};      ///< albedo, 0..1
    float extinction = 0.f;    ///< σt, 1/mm
    glm::vec3 emission{0.f};   ///< linear RGB radiance
    glm::vec3 specular{0.f};   ///< BRDF specular colour F0, 0..1
    float roughness = 1.f;     ///< BRDF roughness, (0, 1]
    float phaseG = kNoPhaseG;  ///< HG asymmetry, (−1, 1); kNoPhaseG (NaN) = the method's phase_g
};
std::ostream& operator<<(std::ostream& os, const TfPoint& p);

/// Optical properties at one value.
struct TfSample {
    float extinction = 0.f;
    glm::vec3 albedo{0.f};
    glm::vec3 emission{0.f};
};

/// The surface channels at one value (interpolated like the colours).
struct TfSurface {
    glm::vec3 specular{0.f};
    float roughness = 1.f;
    float phaseG = kNoPhaseG;  ///< kNoPhaseG when the TF has no phase channel
};

struct Window {
    float level = 0.f;  ///< centre, physical units
    float width = 1.f;  ///< > 0
    float lo() const { return level - 0.5f * width; }
    float hi() const { return level + 0.5f * width; }
};

class TransferFunction {
  public:
    TransferFunction() = default;
    /// Throws InputError(source "transfer function", field "points") unless there is ≥ 1 point,
    /// values strictly increasing and finite, colours and specular in [0,1], extinction and
    /// emission ≥ 0 and finite, roughness in (0, 1], and phaseG in (−1, 1) on every point or
    /// kNoPhaseG on every point. `window` is the reference window (for MIP/MinIP grey and for withWindow).
    TransferFunction(std::vector<TfPoint> points, Window window, std::string name = "custom");

    const std::vector<TfPoint>& points() const { return points_; }
    const Window& window() const { return window_; }
    const std::string& name() const { return name_; }

    /// Exact piecewise-linear evaluation (binary search; slow path, reference for tests).
    TfSample eval(float value) const;
    /// The surface channels, evaluated the same way.
    TfSurface evalSurface(float value) const;
    /// True when the points carry a phase asymmetry g (all of them, by construction).
    bool hasPhaseG() const { return !std::isnan(points_.front().phaseG); }
    /// Largest σt over [lo, hi] (exact: max over the end values and the control points inside).
    float maxExtinction(float lo, float hi) const;
    /// True when σt = 0 on all of [lo, hi].
    bool transparentOver(float lo, float hi) const { return maxExtinction(lo, hi) <= 0.f; }
    /// Largest σt anywhere.
    float maxExtinction() const;

    /// Copy with every σt multiplied by `scale` (≥ 0, the density slider).
    TransferFunction scaledExtinction(float scale) const;
    /// Copy remapped so that the reference window becomes `w` (see header comment).
    TransferFunction withWindow(const Window& w) const;

    /// Value where σt first reaches a tenth of its maximum (the natural isovalue of a surface TF:
    /// where its ramp becomes visible), or the window level when σt is 0 everywhere.
    float surfaceValue() const;

  private:
    std::vector<TfPoint> points_;
    Window window_;
    std::string name_ = "custom";
};
std::ostream& operator<<(std::ostream& os, const TransferFunction& tf);

/// Resampled TF for the per-sample loop, with pre-integration tables. Built once per render.
class TfTable {
  public:
    /// Cells across the TF's point range. 4096 cells over a CT preset's ≈ 3000 HU is < 1 HU per
    /// cell; the pre-integrated lookup is exact for any TF whose breakpoints fall on cell edges and
    /// within a cell's width of exact otherwise.
    static constexpr int kTableCells = 4096;

    explicit TfTable(const TransferFunction& tf);

    /// Linear interpolation of the resampled TF; values outside the range (and NaN, mapped to the
    /// low end) clamp.
    TfSample lookup(float value) const {
        const Position at = position(value);
        const Node& a = nodes_[at.cell];
        const Node& b = nodes_[at.cell + 1];
        TfSample s;
        s.extinction = a.sigma + at.f * (b.sigma - a.sigma);
        s.albedo = a.albedo + at.f * (b.albedo - a.albedo);
        s.emission = a.emission + at.f * (b.emission - a.emission);
        return s;
    }
    /// The surface channels by the same interpolation (their own table: lookup() stays as small).
    TfSurface surface(float value) const {
        const Position at = position(value);
        const SurfaceNode& a = surface_[at.cell];
        const SurfaceNode& b = surface_[at.cell + 1];
        TfSurface s;
        s.specular = a.specular + at.f * (b.specular - a.specular);
        s.roughness = a.roughness + at.f * (b.roughness - a.roughness);
        s.phaseG = a.phaseG + at.f * (b.phaseG - a.phaseG);  // NaN stays NaN
        return s;
    }
    bool hasPhaseG() const { return hasPhaseG_; }
    /// lookup(value).extinction without the colours (the trackers' and visibility rays' inner
    /// loops read only σt).
    float extinction(float value) const {
        const Position at = position(value);
        const float a = nodes_[at.cell].sigma, b = nodes_[at.cell + 1].sigma;
        return a + at.f * (b - a);
    }
    /// The largest extinction(v) over v ∈ [lo, hi] (lo ≤ hi), exactly as extinction() evaluates
    /// it: the ends and every table node between them (the path tracer's fine majorants).
    float maxExtinction(float lo, float hi) const {
        const Position a = position(lo), b = position(hi);
        float m = std::max(extinction(lo), extinction(hi));
        if (b.cell > a.cell) {
            // Nodes a.cell + 1 … b.cell: two overlapping power-of-two runs of the sparse table
            // (the same maximum as a loop over them; that loop was half of a 256³ CT's majorant
            // grid build under a wide TF).
            const std::size_t first = a.cell + 1, count = b.cell - a.cell;
            const int level = std::bit_width(count) - 1;
            const float* row = sigmaRunMax_.data() + std::size_t(level) * nodes_.size();
            m = std::max({m, row[first], row[b.cell + 1 - (std::size_t(1) << level)]});
        }
        return m;
    }

    /// The smallest extinction(v) over v ∈ [lo, hi] (lo ≤ hi), as maxExtinction finds the
    /// largest (the path tracer's control extinctions for residual ratio tracking).
    float minExtinction(float lo, float hi) const { return extinctionRange(lo, hi).first; }

    /// {minExtinction(lo, hi), maxExtinction(lo, hi)} from one look at the table (the same
    /// numbers).
    std::pair<float, float> extinctionRange(float lo, float hi) const {
        const Position a = position(lo), b = position(hi);
        const float ea = extinction(lo), eb = extinction(hi);
        float mn = std::min(ea, eb), mx = std::max(ea, eb);
        if (b.cell > a.cell) {
            const std::size_t first = a.cell + 1, count = b.cell - a.cell;
            const int level = std::bit_width(count) - 1;
            const std::size_t row = std::size_t(level) * nodes_.size();
            const std::size_t second = b.cell + 1 - (std::size_t(1) << level);
            mx = std::max({mx, sigmaRunMax_[row + first], sigmaRunMax_[row + second]});
            mn = std::min({mn, sigmaRunMin_[row + first], sigmaRunMin_[row + second]});
        }
        return {mn, mx};
    }

    /// Segment quantities of the pre-integrated model for values varying linearly from sf to sb.
    struct Segment {
        float meanExtinction = 0.f;  ///< mean σt over the segment, 1/mm (τ = Δ · meanExtinction)
        glm::vec3 albedo{0.f};       ///< extinction-weighted albedo
        glm::vec3 emission{0.f};     ///< extinction-weighted (1 − a)·e
    };
    Segment segment(float sf, float sb) const {
        // Both ends in a transparent tail: nothing to integrate (the common case, inline).
        if (std::max(sf, sb) <= zeroBelow_ || std::min(sf, sb) >= zeroAbove_) return {};
        return segmentSlow(sf, sb);
    }
    /// The cumulative integrals at one value, as segment() evaluates them. A ray marcher keeps the
    /// last two (SegmentCache): the back value of one segment is the front of the next, so each
    /// value's integrals are evaluated once instead of twice. Results are bit-identical.
    struct Cumulative {
        float value = NAN;  ///< key (bitwise); NaN never matches, so a NaN value is recomputed
        int cell = 0;
        bool haveWeighted = false;
        double x = 0.0, sigma = 0.0;
        double weighted[6];
    };
    struct SegmentCache {
        Cumulative slot[2];
    };
    /// segment(sf, sb) reusing (and updating) `cache`.
    Segment segment(float sf, float sb, SegmentCache& cache) const {
        if (std::max(sf, sb) <= zeroBelow_ || std::min(sf, sb) >= zeroAbove_) return {};
        return segmentSlow(sf, sb, &cache);
    }
    /// The fused form of segment() for ray marchers, for TFs without emission (hasEmission()
    /// false; otherwise use segment()): the cumulative integrals of σt and σt·a at one value, from
    /// one interleaved node fetch, kept by the caller for the next segment (the back value of one
    /// segment is the front of the next). Same double arithmetic as segment(), same results up to
    /// rounding.
    struct Integrals {
        double v[4];  ///< ∫σt, ∫σt·a_r, ∫σt·a_g, ∫σt·a_b from lo() to the value
    };
    [[gnu::always_inline]] Integrals integrals(float value) const {
        const double u = (double(value) - double(lo_)) * invCellD_;
        Integrals out;
        if (u > 0.0 && u < double(kTableCells)) {  // the common case (NaN fails both)
            const int cell = int(u);
            const double x = (u - double(cell)) * cell_;
            const double q = x * x * (0.5 * invCellD_);
            const FusedNode& a = fused_[std::size_t(cell)];
            const FusedNode& b = fused_[std::size_t(cell) + 1];
            for (int c = 0; c < 4; ++c)
                out.v[c] = a.cum[c] + double(a.f[c]) * x + (double(b.f[c]) - double(a.f[c])) * q;
            return out;
        }
        const FusedNode& e = u > 0.0 ? fused_.back() : fused_.front();
        const double x =
            u > 0.0 ? (u - double(kTableCells)) * cell_ : (std::isnan(u) ? 0.0 : u * cell_);
        for (int c = 0; c < 4; ++c) out.v[c] = e.cum[c] + double(e.f[c]) * x;
        return out;
    }
    /// integrals(value).v[0] alone: ∫σt from lo() to the value (the visibility rays' steps).
    [[gnu::always_inline]] double sigmaIntegral(float value) const {
        const double u = (double(value) - double(lo_)) * invCellD_;
        if (u > 0.0 && u < double(kTableCells)) {
            const int cell = int(u);
            const double x = (u - double(cell)) * cell_;
            // One 16-byte node per cell instead of two 48-byte fused nodes: less memory
            // traffic (the visibility rays' gain was within noise on a loaded machine).
            const SigmaNode& a = sigmaNodes_[std::size_t(cell)];
            return a.cum + double(a.f) * x +
                   (double(a.fNext) - double(a.f)) * x * x * (0.5 * invCellD_);
        }
        const FusedNode& e = u > 0.0 ? fused_.back() : fused_.front();
        const double x =
            u > 0.0 ? (u - double(kTableCells)) * cell_ : (std::isnan(u) ? 0.0 : u * cell_);
        return e.cum[0] + double(e.f[0]) * x;
    }
    /// sigmaIntegral(s[i]) for i < n into out[i], four values at a time (AVX2 where compiled for
    /// it): the visibility sweep's sub-step ends, a run of a line at a time. Every value goes
    /// through the same arithmetic wherever it lies in the batch (a tail is padded to four), so
    /// out[i] depends on s[i] alone; it agrees with sigmaIntegral to rounding. Finite s.
    void sigmaIntegrals(const float* s, std::size_t n, double* out) const;
    /// meanExtinction(s[e], integrals[e], s[e + 1], integrals[e + 1]) for e < n into out[e]
    /// (integrals from sigmaIntegrals), 0 where transparentSegment(s[e], s[e + 1]); batched like
    /// sigmaIntegrals (every segment through the same arithmetic).
    void meanExtinctions(const float* s, const double* integrals, std::size_t n, float* out) const;
    /// Mean σt over values varying linearly from sf to sb, from the integrals at both ends
    /// (sigmaIntegral): exact for the table; below kPointSampleFraction of a cell apart, σt at the
    /// mid value.
    [[gnu::always_inline]] float meanExtinction(float sf, double integralF, float sb,
                                                double integralB) const {
        if (!(std::abs(sb - sf) * invCell_ > kPointSampleFraction))
            return extinction(0.5f * (sf + sb));
        return float(std::max((integralB - integralF) / (double(sb) - double(sf)), 0.0));
    }
    /// segment(sf, sb) from the integrals at both ends (see integrals()).
    [[gnu::always_inline]] Segment segment(float sf, const Integrals& a, float sb,
                                           const Integrals& b) const {
        if (!(std::abs(sb - sf) * invCell_ > kPointSampleFraction)) return midpoint(sf, sb);
        const double d = b.v[0] - a.v[0];
        const double sigma = d / (double(sb) - double(sf));
        Segment g;
        if (!(sigma > 0.0)) return g;
        g.meanExtinction = float(sigma);
        const double w = 1.0 / d;
        for (int c = 0; c < 3; ++c)
            g.albedo[c] = float(std::clamp((b.v[1 + c] - a.v[1 + c]) * w, 0.0, 1.0));
        return g;
    }
    bool hasEmission() const { return emissive_; }
    /// Below a hundredth of a cell the integrand is linear to float precision: point-sample.
    static constexpr float kPointSampleFraction = 1e-2f;

    /// σt is 0 on (−∞, zeroBelow()] and [zeroAbove(), ∞).
    float zeroBelow() const { return zeroBelow_; }
    float zeroAbove() const { return zeroAbove_; }
    /// True when segment(sf, sb) is certainly transparent (cheap test).
    bool transparentSegment(float sf, float sb) const {
        return std::max(sf, sb) <= zeroBelow_ || std::min(sf, sb) >= zeroAbove_;
    }
    /// Point-sampled version of segment() at the midpoint value (the fine-stepping reference).
    Segment midpoint(float sf, float sb) const;

    /// Width of one table cell in value units: classification of value ranges is widened by this
    /// much, because linear interpolation of the table can leak σt up to one cell past a
    /// breakpoint.
    float cellWidth() const { return 1.f / invCell_; }
    float invCellWidth() const { return invCell_; }
    float lo() const { return lo_; }
    float hi() const { return hi_; }

    /// σt at the table's nodes and the value range they span: all a visibility field depends on.
    struct ExtinctionProfile {
        float lo = 0.f, hi = 0.f;
        std::vector<float> sigma;  ///< kTableCells + 1 nodes
    };
    ExtinctionProfile extinctionProfile() const { return {lo_, hi_, sigma_}; }

    /// The table's nodes as segment() and lookup() read them, for evaluators of the same model
    /// outside this class (the viewer's GLSL ray caster): per node i at value lo() + i·cell,
    /// the integrands σt, σt·a (RGB), σt·(1−a)·e (RGB) and their cumulative integrals from lo(),
    /// and lookup()'s albedo and emission.
    struct Nodes {
        float lo = 0.f, hi = 1.f;
        double cell = 1.0;  ///< value width of a cell
        std::vector<float> sigma;
        std::vector<std::array<float, 6>> weighted;
        std::vector<double> cumSigma;
        std::vector<std::array<double, 6>> cumWeighted;
        std::vector<glm::vec3> albedo, emission;
    };
    Nodes nodes() const;

  private:
    /// Where a value falls in the table: its cell and the fraction across it (values outside the
    /// range, and NaN, clamp to the ends).
    struct Position {
        std::size_t cell;
        float f;
    };
    Position position(float value) const {
        float u = (value - lo_) * invCell_;
        u = u > 0.f ? u : 0.f;  // also maps NaN to the low end
        u = u < float(kTableCells) ? u : float(kTableCells);
        int i = int(u);
        i = i < kTableCells ? i : kTableCells - 1;
        return {std::size_t(i), u - float(i)};
    }
    Segment segmentSlow(float sf, float sb, SegmentCache* cache = nullptr) const;
    /// Entry of `cache` for `value` (computing σ's integral into the slot `other` does not use).
    Cumulative& cumulative(float value, SegmentCache& cache, const Cumulative* other) const;
    void ensureWeighted(Cumulative& c) const;
    struct Node {
        float sigma;
        glm::vec3 albedo;
        glm::vec3 emission;
    };
    struct SurfaceNode {
        glm::vec3 specular;
        float roughness;
        float phaseG;
    };
    /// Cumulative integral from lo_ of σt at a value (exact for the linearly interpolated table,
    /// linear extension outside the range); `cell`/`x` return where it was evaluated.
    double cumulativeSigma(double value, int& cell, double& x) const;
    /// Same for the six weighted integrands σt·a and σt·(1−a)·e at the same position.
    void cumulativeWeighted(double value, int cell, double x, double out[6]) const;

    float lo_ = 0.f, hi_ = 1.f, invCell_ = 1.f;
    double cell_ = 1.0, invCellD_ = 1.0;
    bool emissive_ = false;                    // some node has σt·(1 − a)·e > 0
    float zeroBelow_ = 0.f, zeroAbove_ = 0.f;  // σt = 0 on (−∞, zeroBelow_] and [zeroAbove_, ∞)
    std::vector<Node> nodes_;                  // kTableCells + 1
    std::vector<SurfaceNode> surface_;         // kTableCells + 1
    bool hasPhaseG_ = false;
    std::vector<float> sigma_;  // integrand σt at nodes
    /// Sparse table of σt maxima: row j, entry i = max of sigma_[i … i + 2^j − 1] (rows of
    /// nodes_.size() entries; past the end, the run is cut at the last node).
    std::vector<float> sigmaRunMax_;
    std::vector<float> sigmaRunMin_;              ///< the same for minima
    std::vector<std::array<float, 6>> weighted_;  // σt·a, σt·(1−a)·e at nodes
    std::vector<double> cumSigma_;                // cumulative integrals at nodes
    std::vector<std::array<double, 6>> cumWeighted_;
    struct FusedNode {
        double cum[4];  ///< cumSigma_, cumWeighted_[0..2]
        float f[4];     ///< sigma_, weighted_[0..2]
    };
    std::vector<FusedNode> fused_;  // kTableCells + 1, interleaved for integrals()
    /// Per cell: ∫σt up to its lower node, σt at its two nodes (sigmaIntegral's hot table).
    struct alignas(16) SigmaNode {
        double cum;
        float f, fNext;
    };
    std::vector<SigmaNode> sigmaNodes_;  // kTableCells
};

/// A closed interval of values; empty when lo > hi (the default).
struct ValueInterval {
    float lo = INFINITY, hi = -INFINITY;
    bool empty() const { return !(lo <= hi); }
    /// Whether [a, b] meets the interval.
    bool meets(float a, float b) const { return a <= hi && b >= lo; }
};

/// The values whose σt may differ between two tables (TfTable::extinction, which interpolates
/// between nodes and clamps outside the range): empty when every node agrees; from one cell below
/// the first differing node to one cell above the last, widened by one more cell against rounding,
/// and unbounded on a side whose end node differs (values beyond the range clamp to it); the whole
/// line when the tables span different value ranges. A TF change that moves only interior points
/// or only colours gives the interval the change touched (or none).
ValueInterval extinctionChange(const TfTable::ExtinctionProfile& before,
                               const TfTable::ExtinctionProfile& after);

}  // namespace voxlight::optics
