// SPDX-License-Identifier: MIT
#pragma once
// The indirect part of PVRT's transfer (Zhang, Dong & Ma 2013 §4.2): volumetric photon mapping
// with photons cast from the volume's boundary and splatted onto the transfer grid.
//
// What it adds: t_k^ind(x) (RGB) at every stored point x of the transfer (transfer.h), the
// in-scattered radiance S(x) = (1/4π)∫ L_in(x, ω) dω (isotropic phase) of the light that the
// incident distant radiance B_k (basis.h) brings to x after 1 … maxScatterings scattering events,
// coloured by the albedos it met, before the albedo of x. Light reaching x unscattered (the direct
// part) is not included: direct.h computes it analytically. With maxScatterings = B − 1 the sum
// direct + indirect is the in-scattered radiance of the path tracer's maxBounces = B.
// Phase: Henyey–Greenstein at every collision with options.phaseG, or the TF's phase g channel at
// the collision's value where the TF has one (the path tracer's rule); the new direction is drawn
// from HG (importance sampling: the phase over its pdf is 1, β is unchanged); g = 0 draws the
// isotropic direction exactly as before. The tracer's scattering mode (BRDF) is not used here.
// Exitance coefficients (transfer.h, n = transfer.exitance): every score is also weighted by
// Ŷ_j(ω_in) of the direction ω_in = −d the scored light arrives from (d the photon's direction
// of flight), added to coefficient j of the row; the track-length and collision estimators then
// estimate (1/4π)∫W(x − y) ∫ L_ind(y, ω) Ŷ_j(ω) dω dy. j = 0 (Ŷ_0 = 1) is the isotropic score.
//
// Photons (units: world mm, 1/mm, radiance in the basis light's units):
//   Source  the faces of the volume box that PathTracer::keptInterval clips to: in index space
//           [0, n−1] per axis (voxel centres), [−½, ½] on an axis of one voxel. Each face is cut
//           into boundary cells of about one transfer-grid step per side (⌈extent / step⌉ cells
//           per side, at least 1); photonsPerCell photons per cell, position uniform in the cell,
//           inward direction d cosine-distributed about the inward normal. Outside the box there
//           is no matter, so the radiance entering through a face from direction −d is B_k(−d),
//           and a photon carries the flux Φ_k = B_k(−d)·π·ΔA / photonsPerCell (ΔA the cell's
//           area in mm²; the cosine and the pdf cos/π cancel). For SH Φ_k may be negative (Zhang
//           allows it): the estimator stays linear and unbiased.
//   Paths   the trajectory does not depend on k: each photon is traced once and carries all m
//           fluxes. Free flights by the path tracer's delta tracking (PathTracer::freeFlight)
//           inside keptInterval — matter removed by clip planes or the crop box never
//           scatters photons; it attenuates them only where it still occludes the light (a
//           section view, shadowsFromRemoved true): a photon entering the kept region through
//           such matter is absorbed at its first real collision there (delta tracking over the
//           part of lightInterval before keptInterval), as the path tracer's light is
//           attenuated by it. Elsewhere removed matter is gone for the light too. At a real collision x_c the throughput β (RGB, the
//           product of the albedos of the earlier collisions, divided by roulette survival) is
//           that of light scattered `s` times so far; then β ×= a(x_c), s += 1, a new (HG, see Phase)
//           direction, Russian roulette once s ≥ rouletteAfter (survival q = max channel of β,
//           clamped to [0.05, 1], as the path tracer), and the path ends after maxScatterings
//           scatterings or when it leaves the box.
//   Estimate one of two estimators of the fluence φ_ind of the light scattered ≥ 1 times (per
//           unit photon flux), smoothed by the poly6 kernel
//             W(r) = 315 / (64π h⁹) · (h² − r²)³,  r < h  (∫W dV = 1)
//           with r the world distance (mm; anisotropic voxels included) between the grid point x
//           and a point y of the photon's path, h = kernelRadiusCells × the largest transfer-grid
//           step (mm) of the three axes. Both add to t_k^ind(x) an unbiased estimate of
//             (1/4π) ∫ W(x − y) φ_ind,k(y) dy
//           (S = φ/4π: the isotropic in-scattered radiance before the albedo of x), and differ in
//           which photon events they score and over which region the integral runs:
//     collision     (Estimator::Collision) at every real collision x_c after s ≥ 1 scatterings
//           with σt(x_c) > 0 (the collision density is σt·φ, so each collision counts
//           Φ_k·β/σt(x_c)):
//             t_k^ind(x) += W(|x − x_c|) · Φ_k · β / (σt(x_c) · 4π);
//           the integral runs over the matter (σt > 0) only.
//     track-length  (Estimator::TrackLength) along every free flight [y0, y1] that starts after
//           s ≥ 1 scatterings (from the collision to the next real collision, or to where the
//           photon leaves the kept region; the expected length a photon travels through dV is
//           φ dV, null collisions of the delta tracking included, so this is unbiased in any
//           medium):
//             t_k^ind(x) += Φ_k · β / 4π · ∫_{y0}^{y1} W(|x − y|) dl,
//           the line integral exact (a polynomial in the distance along the flight:
//           ∫(c² − u²)³ du = c⁶u − c⁴u³ + ⅗c²u⁵ − u⁷/7 with c² = h² − r⊥²). Every photon that
//           scattered once scores along its whole onward path, so it has far less noise than the
//           collision estimator in thin matter, where a photon collides ~once; it costs the grid
//           points of the flights' capsules (radius h) instead of the collisions' balls. Its
//           integral runs over the whole kept region: within h of the matter's boundary it
//           counts the fluence in the empty space beside the matter too (φ is continuous there),
//           where the collision estimator comes out short.
//           Either way: against S(x) itself biased by the blur (≈ (h²/22)·∇²S in smooth matter:
//           the kernel's variance per axis is h²/11); in matter farther than h from empty space
//           both have the same expectation. Empty points (slot −1) get nothing.
//
// Determinism: photon p's random numbers are core::CounterRng(p, seed). Photons are traced in
// fixed batches, their events (collisions or flights) kept in photon order; the splat runs in parallel over
// disjoint z-slabs of the grid, each adding the events that reach it in photon order. So every
// stored value is the same sum in the same order for any thread count (bit-identical).
// Memory: the events of one batch (kPhotonsPerBatch photons, ~40 bytes per collision or flight).
#include <cstdint>

#include "core/progress.h"
#include "pathtrace/path_tracer.h"
#include "pvrt/basis.h"
#include "pvrt/transfer.h"

namespace voxlight::pvrt {

/// What the photons score (see the header comment).
enum class Estimator { Collision, TrackLength };

struct PhotonOptions {
    /// Photons per boundary cell (Zhang's NP: 1/10/100), ≥ 1.
    int photonsPerCell = 10;
    /// Poly6 radius h in transfer-grid steps (the largest axis step; Zhang: h = c·Δl), > 0.
    float kernelRadiusCells = 2.f;
    /// Scattering events a photon may have had before it is splatted (the path tracer's
    /// maxBounces − 1), ≥ 0; 0 adds nothing.
    int maxScatterings = 7;
    /// Scatterings before Russian roulette may end a photon, ≥ 0.
    int rouletteAfter = 3;
    Estimator estimator = Estimator::TrackLength;
    /// Henyey–Greenstein asymmetry of the photons' scattering, (−1, 1) (the path tracer's
    /// phase_g); a TF with a phase g channel overrides it per collision. 0 = isotropic.
    float phaseG = 0.f;
    std::uint64_t seed = 1;
    int threads = 0;  ///< 0 = all
};

struct PhotonStats {
    std::uint64_t photons = 0;     ///< photons cast
    std::uint64_t collisions = 0;  ///< real collisions
    std::uint64_t splats = 0;      ///< collisions (s ≥ 1, σt > 0) or flights splatted
    double seconds = 0.0;
};

/// Photons the tracer handles per batch (bounds the event memory).
inline constexpr std::int64_t kPhotonsPerBatch = std::int64_t(1) << 16;

/// Adds the indirect transfer t_k^ind(x) (RGB) of every basis light to every stored point of
/// `transfer` (see the header comment). `transfer` must be laid out for `medium.volume()` with
/// `basis.size()` basis lights (InternalError otherwise); bad options → InputError (source
/// "pvrt", field = the option's name). Reports stage "indirect transfer (photons)" and throws
/// CancelledError when `progress` is cancelled (the transfer then holds part of the sum).
PhotonStats addIndirectTransfer(const pathtrace::PathTracer& medium, const Basis& basis,
                                Transfer& transfer, const PhotonOptions& options,
                                const core::Progress& progress);

}  // namespace voxlight::pvrt
