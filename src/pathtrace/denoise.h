// SPDX-License-Identifier: MIT
#pragma once
// Edge-avoiding denoiser for the path tracer's progressive mean (issue #13 item 6). Exposure
// Render (Kroes et al. 2012, papers/NOTES.md §4) blends a KNN noise filter into the display by
// the running sample variance; here the filter is guided, and its strength follows each pixel's
// own standard error:
//   - the filter F: `iterations` passes of the à-trous wavelet transform (Dammertz et al. 2010:
//     5×5 B3-spline taps h = (1, 4, 6, 4, 1)/16 per axis, spacing 2^i in pass i) with the
//     edge-stopping weights of SVGF (Schied et al. 2017). A tap q of pixel p weighs
//         h · exp(−|ℓp − ℓq| / (σℓ·√(var_p + var_q) + ε)   luminance, in standard errors of
//                                                         the difference (symmetric: a pixel whose
//                                                         few paths all agreed still takes taps)
//                 − |ap − aq|² / σa²                     first-hit albedo guide
//                 − |np|·|nq|·|n̂p − n̂q|² / σn²          first-hit normal guide: only normals
//                                                         that are coherent (long) stop it
//                 − |zp − zq| / (σz·(|∂x z|·|dx| + |∂y z|·|dy|) + εz))   first-hit depth guide
//     normalised over the taps; var is the variance of the luminance mean (below), smoothed 3×3
//     before the first pass and carried through the passes as Σw²var / (Σw)². The guides are
//     noise-free (PathTracer::guides), so edges in them are never blurred across; edges only in
//     the radiance (a shadow boundary) are kept by the luminance term while they stand above the
//     noise.
//   - the strength s_p ∈ [0, 1]: with σp = Σc kc·seC (the standard error of the luminance mean;
//     Rec. 709 weights kc, channels taken as fully correlated — an upper bound that needs no extra
//     buffer), its relative error r_p = √(3×3 Gaussian of σ²)_p / max(ℓp, floor·ℓ̄) (ℓ̄ = mean
//     luminance of the pixels with light; the 3×3 smoothing because a pixel whose few paths all
//     agree reports 0), and
//         s_p = clamp(ln(r_p / targetError) / ln(fullStrengthFactor), 0, 1):
//     0 (the pixel is untouched, bit for bit) at or below targetError, 1 from fullStrengthFactor ×
//     targetError up. Output: (1 − s_p)·mean_p + s_p·F(mean)_p. As samples accumulate r_p falls as
//     1/√n and the filter fades out by itself; zero variance everywhere returns the input.
// A pixel without noise in its 3×3 neighbourhood (the background, mostly) passes through every
// pass unfiltered (it is exact already, and the filter costs nothing there).
// All four channels (radiance and coverage) are filtered with the same weights. Deterministic:
// every output pixel is a pure function of the inputs (rows in parallel), so the result is the
// same for any thread count.
#include <glm/glm.hpp>
#include <vector>

#include "core/image.h"

namespace voxlight::pathtrace {

/// Per-pixel first-hit guides, row 0 = top. In a volume the first hit is not a surface: each
/// guide is the expectation over the camera ray's first real collision (probability density
/// T(t)·σt(t)), the escaping part (probability T at the far end) counting as background with
/// albedo 0, normal 0 and depth `far`. The expectation is smooth where opacity builds up
/// gradually and a step at a sharp boundary, and deterministic (one quadrature per pixel, no
/// samples): a guide with noise of its own would make the filter blotchy at low spp.
struct Guides {
    int width = 0, height = 0;
    std::vector<glm::vec3> albedo;  ///< expected TF albedo at the first collision (0..1)
    /// Expected unit gradient of the scalar field at the first collision (world): length ≤ 1, short
    /// where the gradient directions disagree along the ray (soft, noisy tissue).
    std::vector<glm::vec3> normal;
    std::vector<float> depth;  ///< expected depth along the view of the first collision (mm)
    bool empty() const { return width == 0 || height == 0; }
};

struct DenoiseOptions {
    /// Pixels whose relative standard error is at most this are untouched (reference mode's
    /// 1 % image error, per pixel).
    double targetError = 0.01;
    /// Full filter strength from this many times targetError up (logarithmic ramp in between).
    double fullStrengthFactor = 8.0;
    /// Dark pixels' relative error is measured against this fraction of the mean lit luminance.
    double darkFloor = 0.1;
    int iterations = 4;  ///< à-trous passes: footprint 2^(iterations+2) − 3 pixels wide
    /// SVGF σℓ, in standard errors. 3 against 4: denoised NRMS at 512² (single scattering, the
    /// 2-s renders of the convergence benchmark) torso 0.095 → 0.090, abdominal CT 0.107 → 0.103,
    /// bonsai 0.085 → 0.083; 2 was no better, 8 worse (torso 0.134).
    float sigmaLuminance = 3.f;
    float sigmaAlbedo = 0.1f;
    float sigmaNormal = 0.5f;  /// 0.25 kept the 4-spp torso noisier (NRMSE 0.32 vs 0.28)
    float sigmaDepth = 1.f;    ///< in depth slopes (SVGF σz)
    float depthFloorMm = 1.f;  ///< εz: depth differences below this never stop the filter
    int threads = 0;           ///< 0 = all
};

struct DenoiseStats {
    double meanStrength = 0.0;      ///< mean s_p over all pixels
    double filteredFraction = 0.0;  ///< pixels with s_p > 0
    double fullFraction = 0.0;      ///< pixels with s_p = 1
    double seconds = 0.0;
};

/// A stand-in for the per-pixel standard error of a 1-spp film, whose own is unknown (one sample
/// has no variance; the tracer reports 0, and the filter left the noisiest image untouched): per
/// pixel and channel the standard deviation of the 3×3 neighbourhood (edge pixels clamped) — one
/// sample's spread where the image is flat, an overestimate at edges, which the guides keep.
core::ImageRGBA neighbourhoodStdError(const core::ImageRGBA& mean);

/// Denoises `mean` (linear RGBA, the path tracer's film) with its per-pixel standard error
/// `stdError` (RGB used) and `guides`, all of one size (VL_CHECK). See the header comment.
core::ImageRGBA denoise(const core::ImageRGBA& mean, const core::ImageRGBA& stdError,
                        const Guides& guides, const DenoiseOptions& options,
                        DenoiseStats* stats = nullptr);

}  // namespace voxlight::pathtrace
