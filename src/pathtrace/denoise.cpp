// SPDX-License-Identifier: MIT
#include "pathtrace/denoise.h"

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "core/color.h"
#include "core/error.h"
#include "core/timing.h"

namespace voxlight::pathtrace {

namespace {

/// B3-spline taps of the à-trous transform (Dammertz et al. 2010).
constexpr float kB3[5] = {1.f / 16.f, 1.f / 4.f, 3.f / 8.f, 1.f / 4.f, 1.f / 16.f};
/// 3×3 Gaussian for the variance before the first pass (SVGF).
constexpr float kG3[3] = {0.25f, 0.5f, 0.25f};
/// Keeps the luminance weight finite where the variance is 0.
constexpr float kLumEpsilon = 1e-10f;

float luminance(const float* px) {
    return core::kLuminanceWeightsF[0] * px[0] + core::kLuminanceWeightsF[1] * px[1] +
           core::kLuminanceWeightsF[2] * px[2];
}

}  // namespace

core::ImageRGBA neighbourhoodStdError(const core::ImageRGBA& mean) {
    const int w = mean.width, h = mean.height;
    core::ImageRGBA se(w, h);
    tbb::parallel_for(0, h, [&](int y) {
        for (int x = 0; x < w; ++x) {
            for (int c = 0; c < 3; ++c) {
                double s = 0.0, s2 = 0.0;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const int qx = std::clamp(x + dx, 0, w - 1),
                                  qy = std::clamp(y + dy, 0, h - 1);
                        const double v = mean.pixels[(std::size_t(qy) * w + qx) * 4 + c];
                        s += v, s2 += v * v;
                    }
                const double m = s / 9.0;
                se.pixels[(std::size_t(y) * w + x) * 4 + c] =
                    float(std::sqrt(std::max(0.0, (s2 - 9.0 * m * m) / 8.0)));
            }
            se.pixels[(std::size_t(y) * w + x) * 4 + 3] = 1.f;
        }
    });
    return se;
}

core::ImageRGBA denoise(const core::ImageRGBA& mean, const core::ImageRGBA& stdError,
                        const Guides& guides, const DenoiseOptions& o, DenoiseStats* stats) {
    core::Stopwatch clock;
    const int w = mean.width, h = mean.height;
    VL_CHECK(stdError.width == w && stdError.height == h);
    VL_CHECK(guides.width == w && guides.height == h);
    const std::size_t n = std::size_t(w) * std::size_t(h);
    VL_CHECK(guides.albedo.size() == n && guides.normal.size() == n && guides.depth.size() == n);
    VL_CHECK(o.targetError > 0.0 && o.fullStrengthFactor > 1.0 && o.iterations >= 0);

    std::unique_ptr<tbb::global_control> limit;
    if (o.threads > 0)
        limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      std::size_t(o.threads));
    auto rows = [&](auto&& f) {
        tbb::parallel_for(0, h, [&](int y) {
            for (int x = 0; x < w; ++x) f(x, y, std::size_t(y) * w + x);
        });
    };

    // Variance of each pixel's luminance mean, and the mean luminance of the lit pixels (a serial
    // sum in pixel order: deterministic).
    std::vector<float> var(n);
    double lumSum = 0.0;
    std::size_t lit = 0;
    for (std::size_t p = 0; p < n; ++p) {
        const float* se = stdError.pixels.data() + 4 * p;
        const float s = core::kLuminanceWeightsF[0] * se[0] + core::kLuminanceWeightsF[1] * se[1] +
                        core::kLuminanceWeightsF[2] * se[2];
        var[p] = s * s;
        const float l = luminance(mean.pixels.data() + 4 * p);
        if (l > 0.f) {
            lumSum += l;
            ++lit;
        }
    }
    const float floorLum = lit ? float(o.darkFloor * lumSum / double(lit)) : 0.f;

    // The variance smoothed 3×3 (a pixel's own few samples may all agree), and the strengths.
    std::vector<float> smoothVar(n), strength(n);
    const float logTarget = float(std::log(o.targetError)),
                invLogRamp = float(1.0 / std::log(o.fullStrengthFactor));
    rows([&](int x, int y, std::size_t p) {
        float sum = 0.f, wsum = 0.f;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                const int qx = x + dx, qy = y + dy;
                if (qx < 0 || qy < 0 || qx >= w || qy >= h) continue;
                const float k = kG3[dx + 1] * kG3[dy + 1];
                sum += k * var[std::size_t(qy) * w + qx];
                wsum += k;
            }
        smoothVar[p] = sum / wsum;
        const float l = std::max(luminance(mean.pixels.data() + 4 * p), floorLum);
        float s = 0.f;
        if (smoothVar[p] > 0.f && l > 0.f) {
            const float rel = std::sqrt(smoothVar[p]) / l;
            s = std::clamp((std::log(rel) - logTarget) * invLogRamp, 0.f, 1.f);
        }
        strength[p] = s;
    });

    double sSum = 0.0;
    std::size_t filtered = 0, full = 0;
    for (float s : strength) {
        sSum += s;
        filtered += s > 0.f;
        full += s >= 1.f;
    }
    core::ImageRGBA out = mean;
    if (filtered > 0 && o.iterations > 0) {
        // Depth slopes per pixel: the smaller one-sided difference, so a step does not widen
        // its own tolerance.
        std::vector<glm::vec2> slope(n);
        rows([&](int x, int y, std::size_t p) {
            const float z = guides.depth[p];
            auto oneSided = [&](int qx, int qy, float& d) {
                if (qx < 0 || qy < 0 || qx >= w || qy >= h) return;
                d = std::min(d, std::abs(guides.depth[std::size_t(qy) * w + qx] - z));
            };
            float dx = INFINITY, dy = INFINITY;
            oneSided(x - 1, y, dx);
            oneSided(x + 1, y, dx);
            oneSided(x, y - 1, dy);
            oneSided(x, y + 1, dy);
            slope[p] = {std::isfinite(dx) ? dx : 0.f, std::isfinite(dy) ? dy : 0.f};
        });

        const float invA = 1.f / (o.sigmaAlbedo * o.sigmaAlbedo);
        const float invN = 1.f / (o.sigmaNormal * o.sigmaNormal);
        std::vector<float> normalLen(n), lum(n);
        rows([&](int, int, std::size_t p) { normalLen[p] = glm::length(guides.normal[p]); });
        // The guides' part of a tap's exponent: q at offset (dx, dy) pixels from p.
        auto guideExponent = [&](std::size_t p, std::size_t q, int dx, int dy) {
            const glm::vec3 da = guides.albedo[q] - guides.albedo[p];
            const float zTol = o.sigmaDepth * (slope[p].x * float(std::abs(dx)) +
                                               slope[p].y * float(std::abs(dy))) +
                               o.depthFloorMm;
            return glm::dot(da, da) * invA +
                   2.f *
                       (normalLen[p] * normalLen[q] -
                        glm::dot(guides.normal[p], guides.normal[q])) *
                       invN +
                   std::abs(guides.depth[q] - guides.depth[p]) / zTol;
        };
        // À-trous passes, ping-ponging colour and variance.
        std::vector<float> cur = mean.pixels, next(cur.size());
        std::vector<float> curVar = smoothVar, nextVar(n);
        for (int it = 0; it < o.iterations; ++it) {
            const int step = 1 << it;
            rows([&](int, int, std::size_t p) { lum[p] = luminance(cur.data() + 4 * p); });
            rows([&](int x, int y, std::size_t p) {
                // No noise within 3×3 (the background, mostly): passed through, not filtered.
                if (!(smoothVar[p] > 0.f)) {
                    std::copy_n(cur.data() + 4 * p, 4, next.data() + 4 * p);
                    nextVar[p] = 0.f;
                    return;
                }
                const float lp = lum[p];
                float acc[4] = {0.f, 0.f, 0.f, 0.f};
                float wsum = 0.f, vsum = 0.f;
                for (int j = -2; j <= 2; ++j) {
                    const int qy = y + j * step;
                    if (qy < 0 || qy >= h) continue;
                    for (int i = -2; i <= 2; ++i) {
                        const int qx = x + i * step;
                        if (qx < 0 || qx >= w) continue;
                        const std::size_t q = std::size_t(qy) * w + qx;
                        const float* cq = cur.data() + 4 * q;
                        // The difference of two estimates, in standard errors of
                        // that difference.
                        const float e = std::abs(lum[q] - lp) /
                                            (o.sigmaLuminance * std::sqrt(curVar[p] + curVar[q]) +
                                             kLumEpsilon) +
                                        guideExponent(p, q, i * step, j * step);
                        const float wq = kB3[i + 2] * kB3[j + 2] * std::exp(-e);
                        for (int c = 0; c < 4; ++c) acc[c] += wq * cq[c];
                        wsum += wq;
                        vsum += wq * wq * curVar[q];
                    }
                }
                // The centre tap has weight h(0)² > 0, so wsum > 0.
                float* np4 = next.data() + 4 * p;
                for (int c = 0; c < 4; ++c) np4[c] = acc[c] / wsum;
                nextVar[p] = vsum / (wsum * wsum);
            });
            cur.swap(next);
            curVar.swap(nextVar);
        }

        // Blend by strength; an untouched pixel keeps its bits.
        rows([&](int, int, std::size_t p) {
            const float s = strength[p];
            if (!(s > 0.f)) return;
            float* op = out.pixels.data() + 4 * p;
            const float* fp = cur.data() + 4 * p;
            for (int c = 0; c < 4; ++c) op[c] = (1.f - s) * op[c] + s * fp[c];
        });
    }
    if (stats) {
        stats->meanStrength = n ? sSum / double(n) : 0.0;
        stats->filteredFraction = n ? double(filtered) / double(n) : 0.0;
        stats->fullFraction = n ? double(full) / double(n) : 0.0;
        stats->seconds = clock.seconds();
    }
    return out;
}

}  // namespace voxlight::pathtrace
