// SPDX-License-Identifier: MIT
#pragma once
// The path tracer's slow, deterministic reference for single scattering under delta lights:
// ARCHITECTURE.md §1's integral
//   L = ∫ T(0,t) σt(t) [ (1 − a)·e + a · Σ_lights p(cos θ) · E · V(x, ω_l) ] dt + T(0,D)·background
// by midpoint quadrature along each camera ray (through the pixel centres, as the path tracer's
// antialias: false), with exact shadows V — the transmittance toward every light by its own
// midpoint quadrature of ∫σt — instead of the SH methods' approximations. A segment of length Δ
// and midpoint σt contributes T·(1 − e^{−σt·Δ})·[…], the integral for a medium constant over the
// segment, with the shadow at its midpoint; the error falls as Δ² where σt is smooth and as Δ at the
// TF's steps, so a step of a few hundredths of a voxel is a reference for a PSNR of 40 dB.
//
// It reads everything from the PathTracer (volume and TF through mediumAt, clip planes and the
// crop box through keptInterval / lightInterval, lights, phaseG, background), so the two see the
// same scene; only the estimator differs — Monte Carlo with delta and ratio tracking there,
// quadrature here. Cost: pixels × camera steps × shadow steps σt lookups (seconds at 64³, 64²).
#include "core/image.h"
#include "core/progress.h"
#include "pathtrace/path_tracer.h"
#include "render/camera.h"

namespace voxlight::pathtrace {

struct MarchOptions {
    double stepMm = 0.1;        ///< camera-ray step (mm), > 0
    double shadowStepMm = 0.1;  ///< shadow-ray step (mm), > 0
    /// false: V = 1 — the unshadowed image, for tests to show that shadows are being compared.
    bool shadows = true;
    int threads = 0;  ///< 0 = all hardware threads
};

/// Camera rays stop once their transmittance is below this: the rest of the ray adds at most
/// this fraction of the brightest radiance behind it (10⁻⁶ is 60 dB below it).
inline constexpr double kMarchTermination = 1e-6;
/// Shadow rays stop once their optical depth exceeds this (V < 2·10⁻⁹, counted as 0).
inline constexpr double kMarchMaxOpticalDepth = 20.0;

/// Single scattering of `tracer`'s scene through the pixel centres of `camera`: RGB = linear
/// radiance + T·background, alpha = 1 − T (the path tracer's film). Requires delta lights only
/// (directional, point; none = the path tracer's headlight), phase scattering without a TF phase
/// channel (options().phaseG is the phase) and a pinhole: throws InputError (source
/// "pathtrace reference") naming what is not supported. The image is the same for any thread
/// count.
core::ImageRGBA marchSingleScattering(const PathTracer& tracer, const render::Camera& camera,
                                      const MarchOptions& options,
                                      const core::Progress& progress = core::Progress::none());

}  // namespace voxlight::pathtrace
