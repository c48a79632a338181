// SPDX-License-Identifier: MIT
#include "analysis/image_metrics.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "core/color.h"
#include "core/error.h"

namespace voxlight::analysis {

namespace {

constexpr const char* kSource = "image metrics";
using Plane = std::vector<double>;
using Mat3 = std::array<std::array<double, 3>, 3>;

std::string sizeText(const ImageRGBA& i) {
    return std::to_string(i.width) + "x" + std::to_string(i.height);
}

void checkImages(const ImageRGBA& reference, const ImageRGBA& test, const MetricOptions& options) {
    if (reference.width != test.width || reference.height != test.height)
        throw InputError(
            kSource, "size",
            "the reference is " + sizeText(reference) + " pixels but the test is " + sizeText(test),
            "compare images of the same size");
    if (reference.width <= 0 || reference.height <= 0)
        throw InputError(kSource, "size", "the images are empty (" + sizeText(reference) + ")",
                         "compare images with at least one pixel");
    VL_CHECK_EQ(reference.pixels.size(), std::size_t(4) * reference.width * reference.height);
    VL_CHECK_EQ(test.pixels.size(), std::size_t(4) * test.width * test.height);
    const std::size_t n = std::size_t(reference.width) * reference.height;
    if (!options.mask.empty()) {
        if (options.mask.size() != n)
            throw InputError(kSource, "mask",
                             "has " + std::to_string(options.mask.size()) + " entries for " +
                                 std::to_string(n) + " pixels",
                             "give one byte per pixel, or an empty mask");
        if (std::none_of(options.mask.begin(), options.mask.end(), [](auto m) { return m != 0; }))
            throw InputError(kSource, "mask", "covers no pixel",
                             "compare images with some coverage, or use no mask");
    }
}

bool covered(const MetricOptions& o, std::size_t i) { return o.mask.empty() || o.mask[i] != 0; }

/// Runs f(y) for every row in parallel.
template <class F>
void forRows(int height, const F& f) {
    tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& r) {
        for (int y = r.begin(); y != r.end(); ++y) f(y);
    });
}

/// Mean over covered pixels: row sums in parallel, added in row order (thread-count independent).
double maskedMean(const ScalarImage& img, const MetricOptions& o) {
    std::vector<double> rowSum(img.height, 0.0);
    std::vector<std::size_t> count(img.height, 0);
    forRows(img.height, [&](int y) {
        for (int x = 0; x < img.width; ++x) {
            const std::size_t i = std::size_t(y) * img.width + x;
            if (!covered(o, i)) continue;
            rowSum[y] += img.values[i];
            ++count[y];
        }
    });
    double s = 0;
    std::size_t c = 0;
    for (int y = 0; y < img.height; ++y) s += rowSum[y], c += count[y];
    return s / double(c);
}

double srgbToLinear(double v) {
    return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}
double linearToSrgb(double v) {
    return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
}

/// Display-encoded RGB in [0, 1] of pixel i (see the header: Linear is clamped, then encoded).
std::array<double, 3> displayRgb(const ImageRGBA& img, std::size_t i, Encoding e) {
    std::array<double, 3> c;
    for (int k = 0; k < 3; ++k) {
        double v = img.pixels[4 * i + k];
        if (!(v > 0)) v = 0;  // NaN → 0
        v = std::min(v, 1.0);
        c[k] = e == Encoding::Linear ? linearToSrgb(v) : v;
    }
    return c;
}

/// Normalised 1-D kernel k(i) ∝ f(i), i ∈ [−r, r].
template <class F>
std::vector<double> kernel(int r, const F& f) {
    std::vector<double> k(2 * r + 1);
    for (int i = -r; i <= r; ++i) k[i + r] = f(double(i));
    return k;
}
double sum(const std::vector<double>& k) {
    double s = 0;
    for (double v : k) s += v;
    return s;
}
std::vector<double> normalised(std::vector<double> k) {
    const double s = sum(k);
    for (double& v : k) v /= s;
    return k;
}

/// Separable filter with replicated borders: `kx` along rows, then `ky` along columns.
Plane filter(const Plane& in, int w, int h, const std::vector<double>& kx,
             const std::vector<double>& ky) {
    const int rx = int(kx.size()) / 2, ry = int(ky.size()) / 2;
    Plane tmp(in.size()), out(in.size());
    forRows(h, [&](int y) {
        const double* row = in.data() + std::size_t(y) * w;
        for (int x = 0; x < w; ++x) {
            double s = 0;
            for (int i = -rx; i <= rx; ++i) s += kx[i + rx] * row[std::clamp(x + i, 0, w - 1)];
            tmp[std::size_t(y) * w + x] = s;
        }
    });
    forRows(h, [&](int y) {
        for (int x = 0; x < w; ++x) {
            double s = 0;
            for (int j = -ry; j <= ry; ++j)
                s += ky[j + ry] * tmp[std::size_t(std::clamp(y + j, 0, h - 1)) * w + x];
            out[std::size_t(y) * w + x] = s;
        }
    });
    return out;
}

// --- FLIP colour spaces -------------------------------------------------------------------------
// Linear sRGB → XYZ (D65), the exact rational form of the sRGB primaries FLIP's code uses.
constexpr Mat3 kRgbToXyz = {{{10135552.0 / 24577794, 8788810.0 / 24577794, 4435075.0 / 24577794},
                             {2613072.0 / 12288897, 8788810.0 / 12288897, 887015.0 / 12288897},
                             {1425312.0 / 73733382, 8788810.0 / 73733382, 70074185.0 / 73733382}}};

Mat3 inverse(const Mat3& m) {
    Mat3 r;
    const double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
                       m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                       m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            const int a = (j + 1) % 3, b = (j + 2) % 3, c = (i + 1) % 3, d = (i + 2) % 3;
            r[i][j] = (m[a][c] * m[b][d] - m[a][d] * m[b][c]) / det;
        }
    return r;
}
std::array<double, 3> mul(const Mat3& m, const std::array<double, 3>& v) {
    return {m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
            m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
            m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2]};
}

struct ColourSpaces {
    Mat3 xyzToRgb = inverse(kRgbToXyz);
    std::array<double, 3> white = mul(kRgbToXyz, {1, 1, 1});  // Xn, Yn, Zn

    std::array<double, 3> rgbToYcc(const std::array<double, 3>& rgb) const {
        const auto xyz = mul(kRgbToXyz, rgb);
        const double x = xyz[0] / white[0], y = xyz[1] / white[1], z = xyz[2] / white[2];
        return {116 * y - 16, 500 * (x - y), 200 * (y - z)};
    }
    std::array<double, 3> yccToRgb(const std::array<double, 3>& ycc) const {
        const double y = (ycc[0] + 16) / 116;
        const std::array<double, 3> xyz = {(ycc[1] / 500 + y) * white[0], y * white[1],
                                           (y - ycc[2] / 200) * white[2]};
        return mul(xyzToRgb, xyz);
    }
    /// Linear RGB → CIELAB, then Hunt-adjusted (a, b scaled by 0.01·L).
    std::array<double, 3> rgbToHuntLab(const std::array<double, 3>& rgb) const {
        const auto xyz = mul(kRgbToXyz, rgb);
        auto f = [](double t) {
            constexpr double d = 6.0 / 29;
            return t > d * d * d ? std::cbrt(t) : t / (3 * d * d) + 4.0 / 29;
        };
        const double fx = f(xyz[0] / white[0]), fy = f(xyz[1] / white[1]),
                     fz = f(xyz[2] / white[2]);
        const double l = 116 * fy - 16;
        return {l, 0.01 * l * 500 * (fx - fy), 0.01 * l * 200 * (fy - fz)};
    }
};

double hyab(const std::array<double, 3>& p, const std::array<double, 3>& q) {
    const double da = p[1] - q[1], db = p[2] - q[2];
    return std::abs(p[0] - q[0]) + std::sqrt(da * da + db * db);
}

// FLIP's published constants (Andersson et al. 2020, §4 and the reference implementation).
constexpr double kQc = 0.7, kPc = 0.4, kPt = 0.95, kQf = 0.5;
constexpr double kFeatureWidthDeg = 0.082;
struct CsfGaussian {
    double a, b;
};
constexpr CsfGaussian kCsfA[] = {{1.0, 0.0047}};
constexpr CsfGaussian kCsfRg[] = {{1.0, 0.0053}};
constexpr CsfGaussian kCsfBy[] = {{34.1, 0.04}, {13.5, 0.025}};
constexpr double kCsfMaxB = 0.04;

/// One channel filtered with a CSF kernel Σ a·sqrt(π/b)·exp(−π²r²/b), r = pixels/ppd degrees,
/// normalised to sum 1 over the (2r+1)² samples; each Gaussian is separable.
template <std::size_t N>
Plane csfFilter(const Plane& in, int w, int h, const CsfGaussian (&terms)[N], double ppd,
                int radius) {
    std::vector<Plane> parts;
    std::vector<double> weights;
    for (const auto& t : terms) {
        const auto e = kernel(radius, [&](double i) {
            const double d = i / ppd;
            return std::exp(-std::numbers::pi * std::numbers::pi * d * d / t.b);
        });
        const double s = sum(e);
        weights.push_back(t.a * std::sqrt(std::numbers::pi / t.b) * s * s);
        const auto k = normalised(e);
        parts.push_back(filter(in, w, h, k, k));
    }
    double total = 0;
    for (double wt : weights) total += wt;
    Plane out(in.size(), 0.0);
    for (std::size_t p = 0; p < parts.size(); ++p)
        for (std::size_t i = 0; i < out.size(); ++i) out[i] += weights[p] / total * parts[p][i];
    return out;
}

/// Positive weights scaled to sum 1, negative ones to sum −1 (FLIP's feature kernels).
std::vector<double> balanced(std::vector<double> k) {
    double pos = 0, neg = 0;
    for (double v : k) (v > 0 ? pos : neg) += v;
    for (double& v : k) v = v > 0 ? v / pos : (v < 0 ? v / -neg : 0.0);
    return k;
}

struct Features {
    Plane edge, point;  ///< gradient magnitudes of the edge and point responses
};
Features features(const Plane& y, int w, int h, double ppd) {
    const double sd = 0.5 * kFeatureWidthDeg * ppd;
    const int r = int(std::ceil(3 * sd));
    auto g = [&](double i) { return std::exp(-i * i / (2 * sd * sd)); };
    const auto smooth = normalised(kernel(r, g));
    const auto edgeK = balanced(kernel(r, [&](double i) { return -i * g(i); }));
    const auto pointK =
        balanced(kernel(r, [&](double i) { return (i * i / (sd * sd) - 1) * g(i); }));
    auto magnitude = [&](const std::vector<double>& k) {
        const Plane fx = filter(y, w, h, k, smooth), fy = filter(y, w, h, smooth, k);
        Plane m(y.size());
        for (std::size_t i = 0; i < m.size(); ++i) m[i] = std::hypot(fx[i], fy[i]);
        return m;
    };
    return {magnitude(edgeK), magnitude(pointK)};
}

}  // namespace

std::vector<std::uint8_t> coverageMask(const ImageRGBA& a, const ImageRGBA& b, float threshold) {
    checkImages(a, b, {});
    const std::size_t n = std::size_t(a.width) * a.height;
    std::vector<std::uint8_t> m(n);
    for (std::size_t i = 0; i < n; ++i)
        m[i] = a.pixels[4 * i + 3] > threshold || b.pixels[4 * i + 3] > threshold;
    return m;
}

ErrorStats errorStats(const ImageRGBA& reference, const ImageRGBA& test,
                      const MetricOptions& options, double peak) {
    checkImages(reference, test, options);
    if (!(peak > 0) || !std::isfinite(peak))
        throw InputError(kSource, "peak", "must be a positive number; got " + std::to_string(peak));
    const int w = reference.width, h = reference.height;
    std::vector<double> diff2(h, 0.0), ref2(h, 0.0);
    std::vector<std::size_t> count(h, 0);
    forRows(h, [&](int y) {
        for (int x = 0; x < w; ++x) {
            const std::size_t i = std::size_t(y) * w + x;
            if (!covered(options, i)) continue;
            for (int k = 0; k < 3; ++k) {
                const double r = reference.pixels[4 * i + k], t = test.pixels[4 * i + k];
                diff2[y] += (t - r) * (t - r);
                ref2[y] += r * r;
            }
            ++count[y];
        }
    });
    double d = 0, r = 0;
    ErrorStats s;
    for (int y = 0; y < h; ++y) d += diff2[y], r += ref2[y], s.pixels += count[y];
    s.mse = d / (3.0 * double(s.pixels));
    s.rmse = std::sqrt(s.mse);
    s.nrmse = d == 0 ? 0.0 : (r == 0 ? std::numeric_limits<double>::infinity() : std::sqrt(d / r));
    s.peak = peak;
    s.psnrDb = s.mse == 0 ? std::numeric_limits<double>::infinity()
                          : 10.0 * std::log10(peak * peak / s.mse);
    return s;
}

SsimResult ssim(const ImageRGBA& reference, const ImageRGBA& test, const MetricOptions& options,
                const SsimOptions& so) {
    checkImages(reference, test, options);
    if (!(so.sigma > 0) || so.radius < 0 || !(so.k1 > 0) || !(so.k2 > 0))
        throw InputError(kSource, "ssim options",
                         "sigma, k1 and k2 must be positive and radius non-negative");
    const int w = reference.width, h = reference.height;
    const std::size_t n = std::size_t(w) * h;
    Plane a(n), b(n), aa(n), bb(n), ab(n);
    forRows(h, [&](int y) {
        for (int x = 0; x < w; ++x) {
            const std::size_t i = std::size_t(y) * w + x;
            auto luma = [&](const ImageRGBA& img) {
                const auto c = displayRgb(img, i, options.encoding);
                return core::luminance(c[0], c[1], c[2]);
            };
            a[i] = luma(reference), b[i] = luma(test);
            aa[i] = a[i] * a[i], bb[i] = b[i] * b[i], ab[i] = a[i] * b[i];
        }
    });
    // Local statistics under the Gaussian window
    const auto k = normalised(
        kernel(so.radius, [&](double i) { return std::exp(-i * i / (2 * so.sigma * so.sigma)); }));
    const Plane ma = filter(a, w, h, k, k), mb = filter(b, w, h, k, k);
    const Plane maa = filter(aa, w, h, k, k), mbb = filter(bb, w, h, k, k),
                mab = filter(ab, w, h, k, k);
    const double c1 = so.k1 * so.k1, c2 = so.k2 * so.k2;  // dynamic range L = 1
    SsimResult r;
    r.map = {w, h, std::vector<float>(n)};
    forRows(h, [&](int y) {
        for (int x = 0; x < w; ++x) {
            const std::size_t i = std::size_t(y) * w + x;
            const double va = maa[i] - ma[i] * ma[i], vb = mbb[i] - mb[i] * mb[i],
                         cov = mab[i] - ma[i] * mb[i];
            r.map.values[i] = float((2 * ma[i] * mb[i] + c1) * (2 * cov + c2) /
                                    ((ma[i] * ma[i] + mb[i] * mb[i] + c1) * (va + vb + c2)));
        }
    });
    r.mean = maskedMean(r.map, options);
    return r;
}

FlipResult flip(const ImageRGBA& reference, const ImageRGBA& test, const MetricOptions& options,
                const FlipOptions& fo) {
    checkImages(reference, test, options);
    const double ppd = fo.pixelsPerDegree;
    if (!(ppd > 0) || ppd > 10000)
        throw InputError(kSource, "pixels per degree",
                         "must be in (0, 10000]; got " + std::to_string(ppd),
                         "67 is a 4K monitor 0.7 m wide seen from 0.7 m");
    const int w = reference.width, h = reference.height;
    const std::size_t n = std::size_t(w) * h;
    const ColourSpaces cs;

    // Into the opponent space YyCxCz
    auto opponent = [&](const ImageRGBA& img) {
        std::array<Plane, 3> p{Plane(n), Plane(n), Plane(n)};
        forRows(h, [&](int y) {
            for (int x = 0; x < w; ++x) {
                const std::size_t i = std::size_t(y) * w + x;
                auto c = displayRgb(img, i, options.encoding);
                for (double& v : c) v = srgbToLinear(v);
                const auto ycc = cs.rgbToYcc(c);
                for (int k = 0; k < 3; ++k) p[k][i] = ycc[k];
            }
        });
        return p;
    };
    const auto refYcc = opponent(reference), testYcc = opponent(test);

    // Colour pipeline: CSF filtering, back to clamped linear RGB, Hunt-adjusted CIELAB, HyAB
    const int radius =
        int(std::ceil(3 * std::sqrt(kCsfMaxB / (2 * std::numbers::pi * std::numbers::pi)) * ppd));
    auto huntLab = [&](const std::array<Plane, 3>& ycc) {
        const std::array<Plane, 3> f = {csfFilter(ycc[0], w, h, kCsfA, ppd, radius),
                                        csfFilter(ycc[1], w, h, kCsfRg, ppd, radius),
                                        csfFilter(ycc[2], w, h, kCsfBy, ppd, radius)};
        std::vector<std::array<double, 3>> lab(n);
        forRows(h, [&](int y) {
            for (int x = 0; x < w; ++x) {
                const std::size_t i = std::size_t(y) * w + x;
                auto rgb = cs.yccToRgb({f[0][i], f[1][i], f[2][i]});
                for (double& v : rgb) v = std::clamp(v, 0.0, 1.0);
                lab[i] = cs.rgbToHuntLab(rgb);
            }
        });
        return lab;
    };
    const auto refLab = huntLab(refYcc), testLab = huntLab(testYcc);
    const double cmax = std::pow(hyab(cs.rgbToHuntLab({0, 1, 0}), cs.rgbToHuntLab({0, 0, 1})), kQc);

    // Feature pipeline on the unfiltered achromatic channel, normalised to [0, 1]
    auto achromatic = [&](const std::array<Plane, 3>& ycc) {
        Plane y(n);
        for (std::size_t i = 0; i < n; ++i) y[i] = (ycc[0][i] + 16) / 116;
        return y;
    };
    const Features fr = features(achromatic(refYcc), w, h, ppd);
    const Features ft = features(achromatic(testYcc), w, h, ppd);

    // Combine: FLIP = ΔEc^(1 − ΔEf)
    FlipResult r;
    r.map = {w, h, std::vector<float>(n)};
    forRows(h, [&](int y) {
        for (int x = 0; x < w; ++x) {
            const std::size_t i = std::size_t(y) * w + x;
            const double dc = std::pow(hyab(refLab[i], testLab[i]), kQc);
            const double ec = dc < kPc * cmax
                                  ? kPt / (kPc * cmax) * dc
                                  : kPt + (dc - kPc * cmax) / (cmax - kPc * cmax) * (1 - kPt);
            const double df =
                std::max(std::abs(fr.edge[i] - ft.edge[i]), std::abs(fr.point[i] - ft.point[i]));
            const double ef = std::clamp(std::pow(df / std::numbers::sqrt2, kQf), 0.0, 1.0);
            r.map.values[i] = float(std::clamp(std::pow(std::min(ec, 1.0), 1 - ef), 0.0, 1.0));
        }
    });
    r.mean = maskedMean(r.map, options);
    return r;
}

double detectionFraction(const ScalarImage& flipMap, const MetricOptions& options,
                         const DetectionOptions& detection) {
    if (!(detection.threshold >= 0 && detection.threshold < 1))
        throw InputError(kSource, "detection threshold",
                         "must be in [0, 1); got " + std::to_string(detection.threshold));
    VL_CHECK_EQ(flipMap.values.size(), std::size_t(flipMap.width) * flipMap.height);
    if (!options.mask.empty() && options.mask.size() != flipMap.values.size())
        throw InputError(kSource, "mask",
                         "has " + std::to_string(options.mask.size()) + " entries for " +
                             std::to_string(flipMap.values.size()) + " pixels");
    ScalarImage above = flipMap;
    for (float& v : above.values) v = v > detection.threshold ? 1.0f : 0.0f;
    if (!options.mask.empty() &&
        std::none_of(options.mask.begin(), options.mask.end(), [](auto m) { return m != 0; }))
        throw InputError(kSource, "mask", "covers no pixel");
    return maskedMean(above, options);
}

void magma(float t, float rgb[3]) {
    // matplotlib's magma at t = 0, 1/16, …, 1
    static constexpr float kStops[17][3] = {
        {0.001462f, 0.000466f, 0.013866f}, {0.039608f, 0.031090f, 0.133515f},
        {0.113094f, 0.065492f, 0.276784f}, {0.211718f, 0.061992f, 0.418647f},
        {0.316654f, 0.071690f, 0.485380f}, {0.414709f, 0.110431f, 0.504662f},
        {0.512831f, 0.148179f, 0.507648f}, {0.613617f, 0.181811f, 0.498536f},
        {0.716387f, 0.214982f, 0.475290f}, {0.816914f, 0.255895f, 0.436461f},
        {0.904281f, 0.319610f, 0.388137f}, {0.960949f, 0.418323f, 0.359630f},
        {0.986700f, 0.535582f, 0.382210f}, {0.996096f, 0.653659f, 0.446213f},
        {0.996898f, 0.769591f, 0.534892f}, {0.992440f, 0.884330f, 0.640099f},
        {0.987053f, 0.991438f, 0.749504f}};
    const float s = std::clamp(t, 0.0f, 1.0f) * 16.0f;
    const int i = std::min(int(s), 15);
    const float f = s - float(i);
    for (int k = 0; k < 3; ++k) rgb[k] = kStops[i][k] + f * (kStops[i + 1][k] - kStops[i][k]);
}

ImageRGBA errorMap(const ScalarImage& error, const ErrorMapOptions& options) {
    if (!(options.maxValue > 0) || !std::isfinite(options.maxValue))
        throw InputError(kSource, "error map maximum",
                         "must be a positive number; got " + std::to_string(options.maxValue));
    VL_CHECK_EQ(error.values.size(), std::size_t(error.width) * error.height);
    ImageRGBA out(error.width, error.height);
    forRows(error.height, [&](int y) {
        for (int x = 0; x < error.width; ++x) {
            const float e = error.at(x, y);
            float* p = out.at(x, y);
            if (std::isnan(e)) {
                p[0] = 1, p[1] = 0, p[2] = 1;
            } else {
                magma(e / options.maxValue, p);
            }
            p[3] = 1;
        }
    });
    return out;
}

std::ostream& operator<<(std::ostream& os, const ErrorStats& s) {
    return os << "ErrorStats{rmse " << s.rmse << ", nrmse " << s.nrmse << ", psnr " << s.psnrDb
              << " dB (peak " << s.peak << "), " << s.pixels << " pixels}";
}
std::ostream& operator<<(std::ostream& os, const SsimResult& r) {
    return os << "SsimResult{mean " << r.mean << ", map " << r.map.width << "x" << r.map.height
              << "}";
}
std::ostream& operator<<(std::ostream& os, const FlipResult& r) {
    return os << "FlipResult{mean " << r.mean << ", map " << r.map.width << "x" << r.map.height
              << "}";
}
std::ostream& operator<<(std::ostream& os, Encoding e) {
    return os << (e == Encoding::Display ? "display" : "linear");
}

}  // namespace voxlight::analysis
