// SPDX-License-Identifier: MIT
#pragma once
// Monte-Carlo volume path tracer of ARCHITECTURE.md §1 (Exposure Render, Kroes et al. 2012, with
// the majorant grid it lacked): the reference every fast method is measured against.
//
// Free flights by delta (Woodcock) tracking through a majorant grid: a DDA through the skip cells
// (empty ones crossed in jumps over their skip distances) and, inside each non-empty one, through
// its voxel cells, each with its own majorant — the largest σt the TF table gives over the value
// range of the cell's 8 corners (trilinear values stay within it), built when the tracer is
// made. One exponential optical depth is spent across the cells (majorant × length each), so a
// cell crossed without a collision costs no logarithm. Shadow rays by residual ratio tracking
// (Novák et al. 2014) over the same pieces: each voxel cell also keeps a control, the smallest σt
// over the same value range; its transmittance is taken in closed form and only the residual
// σt − control is tracked (fewer lookups, less variance: at 16 spp the raw NRMS of a 512² render
// fell from 0.137 to 0.105 on the bonsai CT, 0.162 to 0.156 on the torso), stopping at zero and
// with Russian roulette on small transmittance. At a real collision the estimator adds
// (1 − a)·emission, multiplies the throughput by the albedo a and estimates in-scattering by
// next-event estimation towards every light (MIS, power heuristic, with phase sampling for the
// lights a ray can hit: area and environment) and — for multiple scattering — continues in a
// direction drawn from the phase function (isotropic or Henyey–Greenstein), with Russian roulette
// after a few bounces.
// max_bounces = 1 is single scattering, the optical model the SH methods approximate.
//
// Scattering (Options::scattering): at each real collision the path scatters either by the phase
// function (HG with the TF's phase g channel where it has one, else phaseG) or by the surface
// BRDF of pathtrace/brdf.h around the normal n = ±∇s/|∇s| (central differences of the trilinear
// field, one voxel apart; flipped to face the incoming path). Kroes et al. 2012 (Exposure Render,
// section "Hybrid scattering", eq. 1–2) choose the BRDF with probability
//   P_brdf(x) = α(x) · (1 − exp(−25 · g_f³ · |∇s|_n(x)))
// (the extraction ../shared/papers/kroes2012-…txt lost the formula; NOTES.md §4 restates it),
// where here α(x) = 1 − exp(−σt(x)·h) is the opacity of one voxel step h (the smallest spacing),
// |∇s|_n = |∇s| · h / (value range of the volume) the gradient per voxel normalised by the data's
// range (Exposure Render normalises by the intensity range), and g_f = gradientFactor ∈ [0, 1].
// The choice *is* the medium's scattering model (as in Exposure Render): the event scatters by
// P·f_brdf·|n·wi| + (1 − P)·a·p, each estimated with its own light sampling and MIS exactly as the
// phase function is. A BRDF event's colour is the BRDF's (diffuse a, specular F0): it does not
// multiply by a again. A zero (or non-finite) gradient has no normal: phase, whatever the mode.
// A BRDF or phase event that ends the path (single scattering, or the last bounce) still draws
// one direction from its BRDF or phase function toward the area and environment lights,
// MIS-weighted with its light samples (power heuristic): glossy lobes under an environment map
// and large area lights need it (phase events since 7 December; none is drawn under delta lights
// alone).
//   phase   never the BRDF (the default: the optical model of ARCHITECTURE.md §1 that every
//           other method approximates, so the reference stays comparable)
//   brdf    always the BRDF where the gradient is non-zero
//   hybrid  P_brdf as above; gradientFactor 0 gives the phase image bit for bit (no extra random
//           number is drawn where P_brdf = 0)
//
// Camera rays that escape see the background (radiance + T·background, alpha = 1 − T in
// expectation, as the ray caster's film); scattered rays that escape see the environment and area
// lights. No lights in the scene: the ray caster's headlight.
//
// Clip planes and the crop box (render::ClipPlane, render::CropBox) cut camera rays always: the
// camera never sees removed matter, nor scatters off it. For the light each keeps its own
// shadowsFromRemoved:
//   false  the removed matter is gone for the light too: shadow rays and scattered rays ignore it.
//   true   section view: the removed matter only *occludes*. Shadow rays (next-event estimation)
//          are attenuated by it, and a scattered ray that leaves the kept region is attenuated by
//          it on its way to an area or environment light; but no path collides, scatters or emits
//          inside it (it is not part of the picture, only of the light's path), so free flights
//          stay in the kept region.
// Both estimators of the light a scattered ray reaches (next-event and phase sampling) therefore
// see the same transmittance, and MIS stays unbiased.
//
// Memory (accelerationBytes): per voxel of a non-empty skip cell, a copy of the voxels its cells
// read at the volume's own type ((1 + 1/cellSize)³ voxels), and — only where the fine majorants
// of its skip cell differ (a uniform one's single majorant is as tight) — 4 B of fine majorant,
// 4 B of control and 8 B of octant skip distances.
//
// Determinism: every sample's random numbers are a pure function of (pixel, sample index, seed),
// and each pixel sums its samples in order, so the image is the same for any thread count.
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "core/image.h"
#include "core/progress.h"
#include "core/rng.h"
#include "core/volume.h"
#include "grid/brick_traversal.h"
#include "lights/light.h"
#include "optics/transfer_function.h"
#include "pathtrace/denoise.h"
#include "render/camera.h"
#include "render/ray_caster.h"

namespace voxlight::pathtrace {

/// Which scattering function a real collision uses (see the header comment).
enum class Scattering { Phase, Brdf, Hybrid };

struct Options {
    int samplesPerPixel = 64;  ///< the most samples per pixel (a target error may stop sooner)
    /// > 0: a time cap: the first pass is two samples per pixel (it always runs), the passes after
    /// it shrink to what fits in the time left, and the render stops within about one sample per
    /// pixel of the cap.
    double maxSeconds = 0.0;
    /// > 0: stop after the pass whose estimated relative error (Stats::relativeStdError) is at
    /// most this, once kMinSamplesForErrorStop samples are in.
    double targetError = 0.0;
    int maxBounces = 1;  ///< scattering events per path (1 = single scattering)
    float phaseG = 0.f;  ///< Henyey–Greenstein asymmetry, (−1, 1); 0 = isotropic
                         ///< (a TF with a phase g channel overrides it)
    Scattering scattering = Scattering::Phase;
    float gradientFactor = 0.5f;  ///< Kroes' g_f for Scattering::Hybrid, [0, 1]
    int rouletteAfter = 3;        ///< bounces before Russian roulette may end a path
    bool majorantGrid = true;     ///< false: one global majorant (Exposure Render's scheme)
    /// Adaptive sampling: after kAdaptiveWarmupSamples uniform samples, each pass's samples (the
    /// same total as a uniform pass) go to the pixels in proportion to their noise — the standard
    /// deviation of one sample's luminance, 3×3-averaged, floored at kAdaptiveFloor of the mean —
    /// which minimises the image's squared error for the budget (n_p ∝ σ_p). Consistent, not
    /// unbiased (a pixel's count depends on its samples): never in reference renders.
    bool adaptive = false;
    /// Samples spread over each pixel's area (antialiased photo); false: through its centre, as
    /// the ray caster and the SH methods sample — for pixel-by-pixel references.
    bool pixelJitter = true;
    /// Thin lens: diameter (mm; 0 = pinhole) and focus distance along the view (mm; 0 = autofocus
    /// on the first visible surface at the image centre — PathTracer::autofocus).
    double apertureMm = 0.0;
    double focusMm = 0.0;
    std::uint64_t seed = 1;
    int threads = 0;
    glm::vec3 background{0.f};
    std::vector<render::ClipPlane> clipPlanes;
    std::optional<render::CropBox> cropBox;
    std::vector<std::shared_ptr<const lights::Light>> lights;
};

struct Stats {
    /// Samples per pixel taken over all passes (a time cap shrinks the last ones): with adaptive
    /// sampling the mean over the pixels (the same total), each pixel's own count between
    /// minPixelSamples and maxPixelSamples.
    int samplesPerPixel = 0;
    int minPixelSamples = 0, maxPixelSamples = 0;
    bool adaptive = false;
    std::uint64_t paths = 0, realCollisions = 0, nullCollisions = 0, shadowRays = 0;
    /// Real collisions that scattered by the BRDF (hybrid/brdf scattering).
    std::uint64_t surfaceEvents = 0;
    /// Samples whose σt exceeded the cell's majorant (would bias delta tracking): 0 when the
    /// majorants are right; counted, never silently ignored.
    std::uint64_t majorantViolations = 0;
    /// Flights and shadow rays that hit the null-collision budget (a partly empty cell under an
    /// extreme σt): taken as blocked there. 0 for ordinary TFs.
    std::uint64_t budgetExceeded = 0;
    double seconds = 0.0;
    /// The image's estimated relative error: √(mean over covered pixels and R, G, B of the
    /// variance of the pixel's mean) / (mean covered RGB value) — the NRMS error against the
    /// converged image that the samples predict (noise only; the estimator has no bias), in the
    /// convergence benchmark's terms. 0 for a black image; NaN (unknown: JSON null) after one
    /// sample per pixel, which has no spread (it read 0). (Until 7 December it was the
    /// luminance's: on coloured multiple-scattering images 15–24 % under the RGB error measured.)
    double relativeStdError = 0.0;
    /// The same noise in analysis::ErrorStats::nrmse's terms (normalised by the image's RMS value
    /// instead of its mean): √(Σ variance / Σ mean²) over covered pixels and RGB — the nrmse a
    /// perfect method would show against this image, so the floor of an accuracy sweep.
    double expectedNrmse = 0.0;
    bool targetReached = false;         ///< a target error was given and met
    double focusMm = 0.0;               ///< the plane in focus (aperture > 0)
    bool autofocused = false;           ///< focusMm came from autofocus
    std::size_t accelerationBytes = 0;  ///< PathTracer::accelerationBytes
};

/// Fewer samples than this do not trust their own variance estimate (a pixel whose first few
/// paths all missed the light looks noise-free): the target-error stop waits for them.
inline constexpr int kMinSamplesForErrorStop = 16;
/// Adaptive sampling: uniform samples per pixel before the noise decides (its 3×3 average then
/// rests on 36 samples; against 8: the abdominal CT at 512² 4–6 % lower NRMS for the same
/// seconds, raw and denoised, one run at 1 and 2 s each) ...
inline constexpr int kAdaptiveWarmupSamples = 4;
/// ... the least share of the mean noise weight any pixel keeps (every pixel goes on being sampled
/// at ≥ this fraction of the mean rate, so a pixel whose first paths all agreed by chance — a rare
/// bright path not yet seen — is not starved) ...
inline constexpr double kAdaptiveFloor = 0.1;
/// ... and the most samples one pixel takes in one pass (in units of the uniform pass), so that a
/// few very noisy pixels cannot take a whole pass.
inline constexpr int kAdaptiveMaxPassFactor = 4;

/// A ray in world millimetres.
struct Ray {
    glm::dvec3 origin;
    glm::dvec3 direction;  ///< unit
};

class PathTracer {
  public:
    /// `cells`: majorant σt per skip cell under `table`'s TF (render::buildSkipCells with an
    /// emission-absorption or gradient mode). Throws InputError (source "pathtrace") on bad
    /// options.
    PathTracer(std::shared_ptr<const core::Volume> volume,
               std::shared_ptr<const optics::TfTable> table,
               std::shared_ptr<const grid::BrickMajorants> cells, Options options);

    /// Progressive render: passes of samples until samplesPerPixel (or maxSeconds). RGB = mean
    /// radiance (linear), alpha = mean coverage. `stdError`, when given, receives the per-pixel
    /// standard error of the RGB mean.
    core::ImageRGBA render(const render::Camera& camera, const core::Progress& progress,
                           Stats* stats = nullptr, core::ImageRGBA* stdError = nullptr) const;

    // Building blocks, public for the unbiasedness tests.
    /// The part [t0, t1] of `ray` inside the volume box and the kept region (every clip plane and
    /// the crop box: where paths may collide); false when empty.
    bool keptInterval(const Ray& ray, double& t0, double& t1) const;
    /// The part [t0, t1] of `ray` inside the volume box and the region whose matter occludes
    /// light: only the planes (and crop box) with shadowsFromRemoved false cut it. Contains the
    /// kept region. False when empty.
    bool lightInterval(const Ray& ray, double& t0, double& t1) const;
    /// Delta tracking from t0: the distance of the first real collision before t1, or nullopt.
    std::optional<double> freeFlight(const Ray& ray, double t0, double t1,
                                     core::CounterRng& rng) const;
    /// Ratio-tracking estimate of the transmittance toward a light along `ray` over [0, maxT]
    /// (clipped to lightInterval: matter removed with shadowsFromRemoved true still occludes).
    double transmittance(const Ray& ray, double maxT, core::CounterRng& rng) const;
    /// A piece of a ray under one majorant (mm along the ray, σt bound per mm).
    struct Piece {
        double t0, t1;
        float majorant;
        float control = 0.f;  ///< a lower bound of σt over the piece (residual ratio tracking)
    };
    /// The pieces of [t0, t1] with a majorant > 0 that delta and ratio tracking walk (the
    /// majorant grid's traversal with its skip-distance jumps), in order: every point with
    /// σt > 0 must lie in one whose majorant bounds it.
    std::vector<Piece> majorantPieces(const Ray& ray, double t0, double t1) const;
    /// Brute-force check of the skip structures: for every cell (skip cells and the voxel cells
    /// of each non-empty skip cell whose fine majorants are not uniform) and octant, the cube its octant skip distance promises empty
    /// is scanned for a non-empty cell. Returns {entries checked, entries whose cube is not
    /// empty} (the second is 0 when right).
    std::pair<std::uint64_t, std::uint64_t> checkSkipDistances() const;
    /// σt at a world point (TF table lookup of the trilinear value).
    float extinctionAt(const glm::dvec3& p) const;
    /// σt, albedo and emission at a world point (the same lookup; what a real collision there
    /// reads).
    optics::TfSample mediumAt(const glm::dvec3& p) const;
    /// Kroes' P_brdf at a world point under these options (0 for Scattering::Phase; 1 for Brdf
    /// where the gradient is non-zero), and the gradient (value/mm, world) it used.
    double brdfProbabilityAt(const glm::dvec3& p, glm::dvec3* gradient = nullptr) const;
    /// Autofocus: the depth along the view (mm) where the ray through the image centre has lost
    /// half its light (optical depth ln 2, marched at a quarter voxel in the kept region) — the
    /// first visible surface; the depth of the volume's centre when that ray stays clear.
    double autofocus(const render::Camera& camera) const;
    /// The denoiser's first-hit guides (denoise.h Guides) for `camera`'s pixels: the mean of the
    /// pinhole rays through the pixel's four corners (shared with its neighbours: one ray per
    /// pixel; the radiance averages over the pixel's area too, so a pixel on a silhouette gets a
    /// mixed guide like its neighbours along the silhouette, not a unique one; with a lens the
    /// guides stay in focus everywhere), each the expectations over its first collision by
    /// quadrature — T·(1 − e^{−σt·Δ}) per step of at most
    /// kGuideStepVoxels voxels through the pieces of non-zero majorant, in the kept region, until
    /// T < kGuideTransmittance — with the gradient by central differences (world). Deterministic
    /// and noise-free; costs about one ray-cast frame.
    Guides guides(const render::Camera& camera) const;

    const Options& options() const { return options_; }
    /// Bytes of the majorant grid's acceleration data built with the tracer (fine majorants,
    /// octant skip distances, the blocks' voxel copies and their per-block tables; the skip cells
    /// passed in are not counted): what the tracer holds beyond its inputs.
    std::size_t accelerationBytes() const;
    /// The TF table the tracer reads.
    const optics::TfTable& table() const;
    /// The volume the tracer reads (its geometry places the box keptInterval clips to).
    const core::Volume& volume() const;

  private:
    struct Impl;
    std::shared_ptr<const Impl> impl_;
    Options options_;
};

/// Henyey–Greenstein phase function value for cos θ between the propagation directions.
float henyeyGreenstein(float cosTheta, float g);
/// Draws a direction from HG around `forward` (unit) with u ∈ [0,1)².
glm::dvec3 sampleHenyeyGreenstein(const glm::dvec3& forward, float g, float u1, float u2);

}  // namespace voxlight::pathtrace
