// SPDX-License-Identifier: MIT
#pragma once
// Image metrics: how far a test image is from a reference image, as numbers and per-pixel maps.
//
// References
//   SSIM  Z. Wang, A. C. Bovik, H. R. Sheikh, E. P. Simoncelli, "Image Quality Assessment: From
//         Error Visibility to Structural Similarity", IEEE TIP 13(4), 2004.
//   FLIP  P. Andersson, J. Nilsson, T. Akenine-Möller, M. Oskarsson, K. Åström, M. D. Fairchild,
//         "FLIP: A Difference Evaluator for Alternating Images", Proc. ACM CGIT 3(2), 2020 (LDR-FLIP).
//   Detection fraction: J. Kronander, D. Jönsson, J. Löw, P. Ljung, A. Ynnerman, J. Unger,
//         "Efficient Visibility Encoding for Dynamic Illumination in Direct Volume Rendering",
//         IEEE TVCG 18(3), 2012, §7 (fraction of pixels whose difference a visual difference
//         predictor says is detectable).
//   Error-map colours: matplotlib's "magma" (van der Walt & Smith, CC0), 17 stops linearly
//         interpolated.
//
// Values. Images are core::ImageRGBA; alpha is never compared. MetricOptions::encoding says what
// the RGB values are:
//   * Display — display-encoded sRGB in 0..1 (what io::readImage returns for PNG/JPEG);
//   * Linear  — linear radiance (EXR, the renderer's film).
// RMSE, NRMSE and PSNR use the values as stored (RGB, all three channels weighted equally): on a
// PNG they measure display-encoded error, on an EXR radiance error. SSIM and FLIP are defined on
// display-encoded images: a Linear image is clamped to [0, 1] and sRGB-encoded first (no tone
// mapping: tone-map HDR images with values above 1 before comparing them this way).
//
// Non-finite values: RMSE, NRMSE and PSNR propagate them (a NaN pixel makes them NaN); SSIM and
// FLIP read NaN and negative values as 0 and values above 1 as 1, like any display.
//
// Coverage. MetricOptions::mask, when not empty, holds one byte per pixel (row 0 = top); the
// scalar results average only over pixels whose byte is non-zero ("covered"). coverageMask() makes
// one from the images' alpha (the renderer's film stores coverage there). The mask selects pixels
// to average; it does not change the windowed filters of SSIM and FLIP, which see every pixel.
// An empty mask covers every pixel. A mask covering no pixel → InputError.
//
// Edges. Every windowed filter (SSIM's Gaussian, FLIP's CSF and feature kernels) replicates the
// border pixels (clamp to edge), so maps have the images' size.
//
// Errors. Images of different sizes → InputError naming both sizes; an empty image, a mask of the
// wrong size or an option out of range → InputError (source "image metrics", field the option).
//
// Determinism. Multithreaded with oneTBB over rows; sums are accumulated per row and then added in
// row order, so every result is bit-identical for any number of threads.
#include <cstdint>
#include <limits>
#include <ostream>
#include <string>
#include <vector>

#include "core/image.h"

namespace voxlight::analysis {

using core::ImageRGBA;

enum class Encoding {
    Display,  ///< display-encoded sRGB values in 0..1 (8/16-bit image files)
    Linear,   ///< linear radiance (EXR, the renderer's film)
};

struct MetricOptions {
    Encoding encoding = Encoding::Display;
    /// One byte per pixel, non-zero = covered; empty = every pixel (see the header comment).
    std::vector<std::uint8_t> mask;
};

/// Pixels where the alpha of `a` or of `b` exceeds `threshold` (the renderer's coverage).
std::vector<std::uint8_t> coverageMask(const ImageRGBA& a, const ImageRGBA& b,
                                       float threshold = 0.0f);

/// A per-pixel scalar image (row 0 = top), e.g. an SSIM or FLIP map.
struct ScalarImage {
    int width = 0, height = 0;
    std::vector<float> values;  ///< width·height values
    float at(int x, int y) const { return values[std::size_t(y) * width + x]; }
};

// --- RMSE, NRMSE, PSNR --------------------------------------------------------------------------
struct ErrorStats {
    double mse = 0;   ///< mean over covered pixels and the 3 RGB channels of (test − reference)²
    double rmse = 0;  ///< sqrt(mse), in the images' units
    /// Relative RMSE: sqrt(Σ(test − reference)² / Σ reference²) over covered pixels and RGB —
    /// the RMSE divided by the reference's RMS value, so it does not depend on the images' scale.
    /// 0 when both are 0; +∞ when the reference is all zero and the test is not.
    double nrmse = 0;
    /// 10·log10(peak² / mse) in dB; +∞ for identical images (mse = 0).
    double psnrDb = 0;
    double peak = 1;         ///< the peak value PSNR used
    std::size_t pixels = 0;  ///< covered pixels averaged
};
/// `peak` is PSNR's peak signal (1 for display-encoded 0..1 images; for linear radiance choose the
/// reference's white); must be > 0.
ErrorStats errorStats(const ImageRGBA& reference, const ImageRGBA& test,
                      const MetricOptions& options = {}, double peak = 1.0);

// --- SSIM ---------------------------------------------------------------------------------------
// Wang et al. 2004 on luma Y' = 0.2126 R' + 0.7152 G' + 0.0722 B' of the display-encoded values
// (dynamic range L = 1): local means, variances and covariance under an 11×11 Gaussian window
// (σ = 1.5, normalised to sum 1), SSIM = (2μxμy + C1)(2σxy + C2) / ((μx² + μy² + C1)(σx² + σy² + C2))
// with C1 = (K1·L)², C2 = (K2·L)², K1 = 0.01, K2 = 0.03. Differences from Wang's MATLAB code:
// borders are replicated instead of cropped (the map has the image's size) and large images are
// not downsampled first.
struct SsimOptions {
    double k1 = 0.01, k2 = 0.03;
    double sigma = 1.5;  ///< window σ in pixels
    int radius = 5;      ///< window half-size: (2·radius+1)² pixels
};
struct SsimResult {
    double mean = 1;  ///< mean SSIM over covered pixels, in [−1, 1]; 1 = identical
    ScalarImage map;  ///< per-pixel SSIM
};
SsimResult ssim(const ImageRGBA& reference, const ImageRGBA& test,
                const MetricOptions& options = {}, const SsimOptions& ssimOptions = {});

// --- FLIP (LDR) ---------------------------------------------------------------------------------
// Per the paper's description (§3–4) and its published constants:
//  1. Colour pipeline. sRGB → linear RGB → XYZ (D65) → the linearised opponent space YyCxCz
//     (Yy = 116·Y/Yn − 16, Cx = 500·(X/Xn − Y/Yn), Cz = 200·(Y/Yn − Z/Zn)). Each channel is
//     filtered with the spatial kernel of its contrast sensitivity function, a sum of Gaussians
//     s(r) = Σ a·sqrt(π/b)·exp(−π²r²/b), r in degrees (achromatic a=1, b=0.0047; red-green a=1,
//     b=0.0053; blue-yellow a1=34.1, b1=0.04, a2=13.5, b2=0.025), sampled at 1/ppd degrees over
//     a radius ceil(3·sqrt(0.04/(2π²))·ppd) pixels and normalised to sum 1. The filtered image goes
//     back to linear RGB, is clamped to [0, 1], converted to CIELAB and Hunt-adjusted
//     (a, b scaled by 0.01·L). The colour difference is HyAB: |ΔL| + sqrt(Δa² + Δb²), raised to
//     qc = 0.7 and remapped with the paper's piecewise-linear curve (pc = 0.4, pt = 0.95) against
//     the largest difference, that of pure green vs pure blue, to ΔEc ∈ [0, 1].
//  2. Feature pipeline. On the unfiltered achromatic channel (Yy + 16)/116 ∈ [0, 1], edges (first
//     derivative of a Gaussian) and points (second derivative), σ = 0.5·0.082·ppd pixels, radius
//     ceil(3σ), positive and negative weights each normalised to sum ±1; gradient magnitudes of
//     the x and y responses. ΔEf = (max(|‖edge_r‖ − ‖edge_t‖|, |‖point_r‖ − ‖point_t‖|) / √2)^qf,
//     qf = 0.5, clamped to [0, 1].
//  3. FLIP = ΔEc^(1 − ΔEf) ∈ [0, 1]; 0 = no perceivable difference.
// Simplifications: LDR-FLIP only (no HDR-FLIP exposure sweep); the separable Gaussians are applied
// as two 1-D passes (exactly the paper's 2-D kernels, up to float rounding); borders replicated.
// The mean is the arithmetic mean over covered pixels (the paper's pooled value).
struct FlipOptions {
    /// Pixels per degree of visual angle: 67 is the paper's 0.7 m from a 0.7 m wide 4K monitor.
    double pixelsPerDegree = 67.0;
};
struct FlipResult {
    double mean = 0;  ///< mean FLIP over covered pixels, in [0, 1]
    ScalarImage map;  ///< per-pixel FLIP in [0, 1]
};
FlipResult flip(const ImageRGBA& reference, const ImageRGBA& test,
                const MetricOptions& options = {}, const FlipOptions& flipOptions = {});

// --- Detection fraction (Kronander et al. 2012 §7) -----------------------------------------------
// Kronander et al. report the fraction of pixels in which a visual difference predictor detects a
// difference. We substitute FLIP for their predictor: the fraction of covered pixels whose FLIP
// value exceeds `threshold` (strictly). The default 0.05 is our choice (FLIP differences below it
// are hard to see when flipping between the images), not a published calibration.
struct DetectionOptions {
    double threshold = 0.05;  ///< FLIP value above which a pixel counts as detected; in [0, 1)
};
/// Fraction in [0, 1] of covered pixels of `flipMap` above the threshold.
double detectionFraction(const ScalarImage& flipMap, const MetricOptions& options = {},
                         const DetectionOptions& detection = {});

// --- Error maps ---------------------------------------------------------------------------------
// Colours a per-pixel error with magma: `error / maxValue` clamped to [0, 1], 0 → near black
// (0.0015, 0.0005, 0.0139), 1 → pale yellow (0.987, 0.991, 0.750); NaN → magenta (1, 0, 1). The
// result holds display-encoded sRGB (write it to PNG as is), alpha 1.
struct ErrorMapOptions {
    float maxValue = 1.0f;  ///< error shown at the bright end; > 0
};
ImageRGBA errorMap(const ScalarImage& error, const ErrorMapOptions& options = {});
/// The magma colour at t ∈ [0, 1] (clamped), display-encoded sRGB.
void magma(float t, float rgb[3]);

std::ostream& operator<<(std::ostream& os, const ErrorStats& s);
std::ostream& operator<<(std::ostream& os, Encoding e);
std::ostream& operator<<(std::ostream& os, const SsimResult& r);
std::ostream& operator<<(std::ostream& os, const FlipResult& r);

}  // namespace voxlight::analysis
