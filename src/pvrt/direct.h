// SPDX-License-Identifier: MIT
#pragma once
// The direct part of PVRT's transfer (Zhang, Dong & Ma 2013: per voxel, the reduced radiance
// T∞·basis over a set of directions, times the phase): light of basis light k that reaches a
// stored point x unscattered,
//   t_k^dir(x) = (1/4π) ∫ T∞(x, ω) B_k(ω) dω,   T∞(x, ω) = exp(−∫_0^∞ σt(x + sω) ds),
// added equally to R, G and B of every stored point (transfer.h; isotropic phase 1/4π, before the
// albedo). ω points from x toward the distant light; the medium is the box of the voxel centres
// (core::Geometry::worldBounds, as the path tracer), σt = 0 outside it.
//
// Quadrature: the directions ω_j of the icosahedral DSF set of `directions` (42, 162 or 642;
// sh/dsf.h) with weights A_j = its basis solid angles (Σ A_j = 4π), so
//   t_k^dir(x) ≈ (1/4π) Σ_j A_j T∞(x, ω_j) B_k(ω_j).
// With the DSF basis of the same count the directions are the basis directions, B_k(ω_j) = δ_jk,
// and each direction feeds one basis light exactly (t_k = A_k T∞(x, ω_k)/4π).
// Exitance coefficients (transfer.h, n = transfer.exitance > 1): the same quadrature projects
// T∞·B_k onto Ŷ_i instead of integrating it,
//   t_{k,i}^dir(x) ≈ (1/4π) Σ_j A_j T∞(x, ω_j) B_k(ω_j) Ŷ_i(ω_j),
// the same in R, G and B; i = 0 (Ŷ_0 = 1) is the isotropic sum, bit for bit. The sweeps do not
// change; only the accumulation grows ×n (n·m multiply-adds per point and direction for SH).
//
// T∞ for all voxels of one direction at once: a slice sweep (semi-Lagrangian propagation). The
// slices are taken across the axis a on which ω has its largest index-space component, starting
// at the slice nearest the light (T = 1 there: it lies on the box face). A voxel x of the next
// slice takes T(x) = T(x + s·ω)·exp(−τ), where s = the distance (mm) at which x + s·ω lies exactly
// in the previous slice. The transverse offset is the same for every voxel, so the re-sampling
// there is a fixed stencil: the value bilinear (= the trilinear field on that plane), T by a
// Catmull–Rom bicubic clamped to its 4 nearest taps (no new extrema: T stays in [0, 1]; bilinear in
// the ring of voxels next to the box's sides). τ = s·mean σt over the segment, pre-integrated
// (optics::TfTable::meanExtinction) for the value varying linearly between the two ends, so a
// sharp TF step between two voxels gets its exact share. A segment that leaves the box sideways
// ends there (T = 1 beyond). Along an axis the sweep is exact for the trilinear field (up to the
// pre-integration's linear-value assumption). Obliquely, re-sampling T once per slice diffuses it
// numerically: smooth T stays accurate, but a kink or step of T (a shadow edge, the faces of a
// slab) widens by about a voxel; the clamped bicubic halves the mean error of plain bilinear
// re-sampling for ~30 % more time (tests/pvrt/test_direct.cpp measures the errors against closed
// forms and a fine march; its tolerances quote both schemes).
//
// Clip geometry: a clip plane or crop box with shadowsFromRemoved == false removes its matter for
// the light too: σt = 0 outside the kept (convex) region, applied exactly per segment (the kept
// part of each segment, with the value interpolated along it). Planes with shadowsFromRemoved ==
// true are ignored here (their matter still casts shadows).
//
// Parallel within a slice (oneTBB), every voxel computed by the same arithmetic: results are
// bit-identical for any thread count. Memory: the physical values as float in two voxel
// orderings (natural, and x-major so that sweeps across x read contiguous slices), 8 bytes per
// voxel; one float T volume per direction in flight; T at the stored points for a batch of
// kDirectionBatch directions (4·kDirectionBatch bytes per stored point).
// Cost: one sweep per direction over every voxel (128³ torso, 162 directions, 2 cores: a few
// seconds; see the timing test), independent of the basis; the basis only costs the final
// accumulation (m multiply-adds per point and direction for SH, one for DSF).
#include <cstdint>
#include <glm/glm.hpp>
#include <iosfwd>
#include <optional>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"
#include "optics/transfer_function.h"
#include "pvrt/basis.h"
#include "pvrt/transfer.h"
#include "render/ray_caster.h"

namespace voxlight::pvrt {

/// Directions whose transmittance at the stored points is held before they are added into the
/// transfer rows (each row is then read and written once per batch, not once per direction).
inline constexpr int kDirectionBatch = 32;

struct DirectOptions {
    /// Quadrature directions: 42, 162 or 642 (InputError otherwise). With a DSF basis use its own
    /// count (each basis light then gets exactly its direction's T∞); fewer directions than DSF
    /// basis lights leave most basis lights with a few quadrature points in their support.
    int directions = 162;
    int threads = 0;  ///< 0 = all hardware threads
    std::vector<render::ClipPlane> clipPlanes;
    std::optional<render::CropBox> cropBox;
};

struct DirectStats {
    int directions = 0;
    std::uint64_t voxelUpdates = 0;  ///< swept voxels over all directions
    double seconds = 0;
};
std::ostream& operator<<(std::ostream& os, const DirectStats& s);

/// T∞(x, ω) at every voxel centre (x fastest, core::Volume::linearIndex) for the distant light in
/// world direction `towardLight` (normalised here; InternalError if zero), by the slice sweep
/// above. Uses options.threads and the clip geometry; ignores options.directions.
std::vector<float> sweepTransmittance(const core::Volume& volume, const optics::TfTable& table,
                                      const glm::dvec3& towardLight, const DirectOptions& options);

/// Adds t_k^dir to R, G and B of every stored point of `transfer` (its layout must be made for
/// `volume`, its basis count basis.size(); InternalError otherwise). Progress stage "pvrt direct",
/// one report per direction; throws CancelledError when cancelled (the transfer is then partly
/// filled). No stored points: nothing to do (no sweep runs).
DirectStats addDirectTransfer(const core::Volume& volume, const optics::TfTable& table,
                              const Basis& basis, Transfer& transfer, const DirectOptions& options,
                              const core::Progress& progress = core::Progress::none());

/// Trilinear interpolation of a per-voxel float field (x fastest) at continuous voxel coordinate
/// p, clamped to the grid (the transfer's stored points read T this way).
float sampleVoxelField(const std::vector<float>& field, const glm::ivec3& dims, const glm::vec3& p);

}  // namespace voxlight::pvrt
