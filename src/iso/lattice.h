// SPDX-License-Identifier: MIT
#pragma once
// Illumination lattice (Wyman, Parker, Shirley, Hansen 2006 §4; NOTES.md §3): global illumination
// on isosurfaces, precomputed on a 3-D grid of texels and interpolated trilinearly where a surface
// is shaded (mesh vertices for the lit-mesh export, iso/bake.h).
//
// Per texel t at voxel-index position x_t (the lattice spans the voxel centres [0, dims − 1] with
// `resolution` texels per voxel along each axis, Wyman Fig. 12: 1/8, 1, 8):
//   * its own isosurface: the level set s = s(x_t) of the volume's trilinear physical value s
//     through the texel (so one lattice serves every isovalue; a texel is computed once and kept);
//   * its normal n: −∇(B ∗ s)/|…| of the tricubic B-spline smoothed field (4×4×4 voxels), outward,
//     toward lower values (iso/extract.h's convention);
//   * paths start at x_t + ε·n (kStartOffsetVoxels, moved further along n until s < s(x_t)), are
//     traced against the trilinear isosurface of the texel's isovalue — cell by cell, cells whose 8
//     corners (and 8³-cell bricks whose value range) do not contain the isovalue skipped, the
//     crossing inside a candidate cell found exactly on the cubic that trilinear interpolation is
//     along a line (monotone pieces between its critical points, then bisection) — and escape at
//     the volume's boundary;
//   * irradiance E(x_t) = ∫ L_in(x_t, ω) cos θ dω by cosine-weighted Monte Carlo: delta lights
//     (directional, point) by next-event estimation with a shadow ray at every path vertex; the
//     other lights (environment, area) by the radiance they send along an escaping path; surfaces
//     hit reflect as Lambertian with the albedo the transfer function gives the texel's isovalue
//     (the whole isosurface has that albedo), up to `bounces` interreflections.
//   * Texels where the smoothed gradient vanishes (a plateau at the isovalue: no surface) use the
//     full sphere, E = π · mean of L_in over all directions (the cosine term averaged over normals),
//     with only values above theirs occluding; trilinear reads leave them out (weights renormalised
//     over the texels that have a surface) unless all texels read are plateaus — they carry no
//     surface's light, and on sharp-edged data (a phantom's constant inside and outside) they would
//     pull a surface toward what a point in the open sees.
// Stored as
//   * Irradiance: RGB E per texel (static lights; any mix of directional, point, environment and
//     area lights). Changing a light invalidates every texel.
//   * ShTransfer: the irradiance transfer vector T_i = ∫ (path throughput) Y_i(ω_escape) … per RGB
//     channel, i < (order)² (order ≤ 5: 25 coefficients), for *distant* lights only (directional
//     and environment): E = Σ_i ℓ_i ⊙ T_i with the lights' SH coefficients ℓ (lights/light.h), so
//     lights turn and change by re-dotting, without tracing. Delta lights are then band-limited
//     (their shadows blur: Wyman's trade) and ring: the dot is clamped at 0.
// Lazy: `require` computes only the texels that trilinear reads at the given points need (the 2×2×2
// stencil of each point), or those of the cells an isosurface crosses; computed texels are kept, so
// a new isovalue or a refined mesh computes only texels not seen before. Every texel's random
// numbers are a counter-based function of (texel index, sample, seed): a texel's value does not
// depend on thread count, on what else was required or in which order — lazy equals full, bit for
// bit (tested).
// Units: world mm (patient LPS), lights in the scene's radiometric unit (lights/light.h); a
// Lambertian surface of albedo a under E leaves radiance a·E/π, so a white sky of radiance 1 gives
// an unoccluded surface E = π and radiance a.
#include <array>
#include <atomic>
#include <cstdint>
#include <glm/glm.hpp>
#include <memory>
#include <mutex>
#include <span>
#include <unordered_map>
#include <vector>

#include "core/half_space.h"
#include "core/progress.h"
#include "core/volume.h"
#include "iso/mesh.h"
#include "lights/light.h"
#include "optics/transfer_function.h"

namespace voxlight::iso {

enum class LatticeMode { Irradiance, ShTransfer };

/// Which isosurface a texel's paths start on.
enum class TexelPlacement {
    /// Wyman's: the texel's own isosurface s = s(x_t), so one lattice serves every isovalue; on
    /// sharp-edged data (CT bone) the texels around a surface point lie on other surfaces and the
    /// trilinear blend is 0.3–0.5 NRMS off per-point tracing (README, bench_lattice).
    OwnIsosurface,
    /// The isosurface at `surfaceIso`: x_t moved onto it by Newton steps on the trilinear field
    /// (at most kMaxProjectionVoxels), so the 8 texels around a point of that surface all estimate
    /// that surface and interpolation errs only by the irradiance's own variation. Texels with no
    /// such surface point near them are left out of reads (as plateaus). One lattice per isovalue.
    OnSurface,
};

/// OnSurface: farthest a texel is moved onto the surface, voxels. A texel of a cell the surface
/// crosses lies within √3 voxels of it (the cell's diagonal); beyond that margin it reads no
/// surface point and is left out.
inline constexpr double kMaxProjectionVoxels = 2.0;
/// Coarsest lattice (texels per voxel): a coarser texel lies where the field is flat (Newton finds
/// no gradient to follow onto the surface) and is left out, and a vertex whose texels all are
/// reads black — at 0.125 a fifth of a smooth-edged sphere's vertices, at 0.25 11 % of a binary
/// (mask) sphere's; at 0.5 none (Lattice.TheCoarsestLatticeReachesTheSurfaceFromEveryTexel).
inline constexpr double kMinLatticeResolution = 0.5;

/// Start offset along the normal, voxels (Wyman: "slightly"): far enough that float rounding of the
/// start point and the trilinear-vs-B-spline normal mismatch leave the point outside its own
/// isosurface, small next to a voxel so that the texel still represents its own surface.
inline constexpr double kStartOffsetVoxels = 0.05;
/// Largest further walk along the normal to get outside (texels where the smoothed normal and the
/// trilinear field disagree), voxels; beyond it the texel is a plateau and uses the full sphere.
inline constexpr double kMaxStartWalkVoxels = 1.0;
/// A point of a render's isosurface hit this close to the volume's box face (voxels), over a face
/// value ≥ the isovalue, is a cap (the ray caster's hit where matter runs into the box): far above
/// the float rounding of a hit's world position (≈ 1e-4 voxel for a 0.1-mm voxel 500 mm from the
/// origin), far below the voxel a true crossing's normal varies over.
inline constexpr double kCapFaceVoxels = 0.01;
/// Texels per lazy-allocation block edge (8³ texels per block).
inline constexpr int kLatticeBlock = 8;

struct LatticeOptions {
    int samples = 100;        ///< paths per texel, ≥ 1
    int bounces = 1;          ///< diffuse interreflections, 0…16
    double resolution = 1.0;  ///< texels per voxel along each axis, 1/8…8
    LatticeMode mode = LatticeMode::Irradiance;
    int shOrder = 5;  ///< ShTransfer: bands 0…order−1, (order)² coefficients, 1…5
    TexelPlacement placement = TexelPlacement::OwnIsosurface;
    double surfaceIso = NAN;  ///< OnSurface: the isovalue (physical), inside the data's range
    std::uint64_t seed = 0;
    double memoryBudgetMiB = 4096.0;  ///< texel storage; over it → InputError naming the budget
    int threads = 0;                  ///< 0 = all cores
    /// Empty-space skip distances for an isovalue many paths share (the on-surface lattice, the
    /// bake from vertices, the baselines): the same crossings, fewer cells tested. Off only to
    /// measure what they save (bench_lattice).
    bool skipDistances = true;
    /// Matter outside the intersection of these half-spaces is gone for the light (the scene's
    /// clip planes and crop box with shadows_from_removed false); a path that enters the kept
    /// region inside matter meets the cut face. Empty: the whole volume.
    std::vector<core::HalfSpace> keep;
};

/// What one `require` call did.
struct LatticeStats {
    std::uint64_t texelsFull = 0;      ///< texels of the whole lattice (what a full one computes)
    std::uint64_t texelsNeeded = 0;    ///< texels the request reads
    std::uint64_t texelsComputed = 0;  ///< of those, computed by this call
    std::uint64_t texelsReused = 0;    ///< of those, already computed before
    std::uint64_t texelsStored = 0;    ///< computed texels held after the call
    std::uint64_t pathsTraced = 0, shadowRays = 0;
    std::uint64_t plateauTexels = 0;  ///< computed with the full sphere (no surface normal)
    double seconds = 0.0;
    double storedMiB = 0.0;  ///< texel storage after the call
    /// What the tracer holds beside the texels (IlluminationLattice::tracerMiB), after the call.
    double tracerMiB = 0.0;
    std::uint64_t skipFieldsBuilt = 0;  ///< skip fields built so far (skipFieldsBuilt())
};

class IlluminationLattice {
  public:
    /// Throws InputError (source "lattice", the option's name as field) on bad options, a flat
    /// volume, lights the mode cannot take (ShTransfer: point or area lights).
    IlluminationLattice(std::shared_ptr<const core::Volume> volume,
                        const optics::TransferFunction& tf,
                        std::vector<std::shared_ptr<const lights::Light>> lights,
                        const LatticeOptions& options);
    ~IlluminationLattice();
    IlluminationLattice(const IlluminationLattice&) = delete;
    IlluminationLattice& operator=(const IlluminationLattice&) = delete;

    /// Computes the texels trilinear reads at these world points (mm) need. Throws InputError
    /// (field "memory") when the texels would exceed the budget, CancelledError through progress.
    LatticeStats require(std::span<const glm::dvec3> worldPoints,
                         const core::Progress& progress = core::Progress::none());
    /// The same for points on the isosurface at `surfaceIso`: only the texels
    /// irradiance(p, surfaceIso) reads (those inside it, unless none around a point is).
    LatticeStats require(std::span<const glm::dvec3> worldPoints, double surfaceIso,
                         const core::Progress& progress = core::Progress::none());
    /// Computes the texels of every volume cell whose 8 corners span `isovalue` (what direct ray
    /// casting of that isosurface reads).
    LatticeStats requireIsosurface(double isovalue,
                                   const core::Progress& progress = core::Progress::none());

    /// Irradiance at a world point: trilinear over the 8 texels around it (plateau texels left out,
    /// above), each of which must have been required (VL_CHECK). ShTransfer: re-dotted with the
    /// current lights.
    glm::vec3 irradiance(const glm::dvec3& world) const;
    /// The same for a point on the isosurface at `surfaceIso` (values above it inside): texels
    /// outside that surface (value < surfaceIso) are used only where no texel inside it is — their
    /// own isosurfaces lie in the matter around it (on CT, the noise of soft tissue), not on it,
    /// and mixing them in gave the lit torso a mottled, wood-grain texture at voxel scale.
    glm::vec3 irradiance(const glm::dvec3& world, double surfaceIso) const;
    /// ShTransfer only: the transfer vector at a point on the isosurface at `surfaceIso`,
    /// interpolated as irradiance(world, surfaceIso) interpolates (the same texels and weights), so
    /// that max(0, Σ_i ℓ_i ⊙ out_i) with the lights' SH coefficients ℓ is the irradiance up to the
    /// clamp: (order)² RGB entries into `out`.
    void transfer(const glm::dvec3& world, double surfaceIso, std::span<glm::vec3> out) const;
    /// Whether texel t lies outside the surface at surfaceIso (false for NaN: no surface given).
    bool outsideOf(const glm::ivec3& t, double surfaceIso) const;
    /// The stored value of texel (i, j, k) (must be computed): irradiance, or re-dotted transfer.
    glm::vec3 texelIrradiance(const glm::ivec3& t) const;
    /// ShTransfer only: the transfer vector of a computed texel, (order)² RGB entries.
    std::span<const glm::vec3> texelTransfer(const glm::ivec3& t) const;
    bool computed(const glm::ivec3& t) const;
    /// Whether computed texel t is a plateau (no surface through it: the full-sphere value).
    bool plateau(const glm::ivec3& t) const;

    /// The reference the lattice approximates (Wyman's per-pixel path tracing, Fig. 11): the
    /// irradiance at a surface point itself — its own position on the isosurface at `iso`, the
    /// smoothed normal there (on a cap, where matter runs into the volume's box, the face's
    /// outward normal: kCapFaceVoxels) — by `samples` paths with the lattice's lights and bounces, no texels
    /// and no interpolation. Irradiance mode only. `key` seeds its random numbers.
    glm::vec3 pointIrradiance(const glm::dvec3& world, double iso, int samples,
                              std::uint64_t key) const;

    /// Wyman's baselines (Figs. 8–10), at a surface point on the isosurface at `iso` (its smoothed
    /// normal n there, as estimate() uses, or a cap's face normal; zero irradiance where there is
    /// none):
    /// Lambert (shadows false): Σ over the delta lights (directional, point) of E_l · max(0, n·l);
    /// Lambert + hard shadows (true): each term times the visibility of one shadow ray against
    /// the trilinear isosurface. Environment and area lights are not part of these baselines.
    glm::vec3 directIrradiance(const glm::dvec3& world, double iso, bool shadows) const;
    /// Vicinity shading (Stewart 2003): E = ∫ L(ω) V_r(ω) cos θ dω by `samples` cosine-weighted
    /// directions, where V_r is 0 when the isosurface is hit within `radiusMm` and L is the
    /// lattice's environment and area lights (a uniform white sky of radiance 1 when it has none:
    /// the obscurance of the surface) — occlusion only from the vicinity, no delta lights, no
    /// bounces. `key` seeds its random numbers.
    glm::vec3 vicinityIrradiance(const glm::dvec3& world, double iso, double radiusMm, int samples,
                                 std::uint64_t key) const;

    /// New lights. ShTransfer: re-dots (no texel is traced again; distant lights only, as the
    /// constructor). Irradiance: every computed texel is dropped (the next require traces again).
    void setLights(std::vector<std::shared_ptr<const lights::Light>> lights);

    const glm::ivec3& dims() const { return dims_; }  ///< texels per axis
    /// Texel (i, j, k)'s voxel-index position: the texels span the volume's first to last voxel
    /// on every axis, about 1/resolution voxels apart (exactly, when that fits a whole number of
    /// times).
    glm::dvec3 texelIndexPosition(const glm::ivec3& t) const { return glm::dvec3(t) * step_; }
    const LatticeOptions& options() const { return options_; }
    std::uint64_t texelsStored() const { return stored_; }
    /// Isovalues whose skip distances the tracer holds (LatticeOptions::skipDistances; at most 2:
    /// a third replaces the least recently used).
    int skipFieldCount() const;
    /// Skip fields built since construction (one per isovalue, again after a replacement).
    std::uint64_t skipFieldsBuilt() const;
    double storedMiB() const;
    /// The tracer's memory beside the texels: the volume as floats (4 B per voxel), the bricks'
    /// ranges and the skip fields held (1 B per cell each; building one needs ≈ 11 B per cell
    /// more for the time it takes).
    double tracerMiB() const;

  private:
    struct Block;
    struct SkipField;
    struct Tracer;
    std::size_t floatsPerTexel() const;
    Block* blockFor(const glm::ivec3& t) const;
    const float* texelData(const glm::ivec3& t) const;
    LatticeStats computeTexels(std::vector<glm::ivec3> needed, const core::Progress& progress);
    void redot();
    /// What one estimate sums: irradiance (delta lights + the path mean) or the SH transfer mean.
    struct PathSums {
        explicit PathSums(int coefficients)
            : T(std::size_t(coefficients)), y(std::size_t(coefficients)) {}
        glm::dvec3 E{0.0};
        std::vector<glm::dvec3> T;
        std::vector<double> y;  ///< scratch: SH basis values
        bool plateau = false;
        std::uint64_t paths = 0, shadowRays = 0;
    };
    /// `samples` paths from surface point xt (index) on the isosurface at iso (header: start
    /// point, normal, plateaus, lights); random numbers keyed by (key, sample, seed).
    /// `sharedIso`: many calls trace against this isovalue (a bake, the on-surface lattice), so
    /// its skip distances are worth building (Tracer::skipFor); false for Wyman's own-isosurface
    /// texels, each with its own isovalue.
    /// `given`: the skip distances for iso the caller holds (then none is looked up).
    /// `cap`: xt lies on a cap — matter cut by the volume's box face, whose outward world normal
    /// this is (Tracer::capPoint): the paths start there, around it, not from the field's normal
    /// (zero on the plateau inside the cut).
    void estimate(const glm::dvec3& xt, double iso, std::uint64_t key, int samples, bool sharedIso,
                  PathSums& out, const SkipField* given = nullptr,
                  const glm::dvec3* cap = nullptr) const;
    /// The texels irradiance(world, surfaceIso) reads (the preferred group, header) and their
    /// normalised weights; returns how many.
    int surfaceStencil(const glm::dvec3& world, double surfaceIso, glm::ivec3 texel[8],
                       double weight[8]) const;
    /// The texels trilinear reads at a world point (weight > 0) and their weights; returns how many.
    int stencil(const glm::dvec3& world, glm::ivec3 texel[8], double weight[8]) const;
    /// The tracer's skip distances for iso (nullptr when options_.skipDistances is off or the
    /// isovalue is not finite); the caller holds it while it traces.
    std::shared_ptr<const SkipField> skipFor(double iso) const;
    /// ShTransfer: the irradiance slot of texel data d from its transfer and the current lights.
    void dotTexel(float* d) const;

    std::shared_ptr<const core::Volume> volume_;
    optics::TransferFunction tf_;
    std::vector<std::shared_ptr<const lights::Light>> lights_;
    LatticeOptions options_;
    std::unique_ptr<Tracer> tracer_;
    glm::dvec3 step_;  ///< voxels between texels per axis (texelIndexPosition)
    glm::ivec3 dims_, blocks_;
    std::unordered_map<std::uint64_t, std::unique_ptr<Block>> blockMap_;
    std::uint64_t stored_ = 0;
    std::vector<glm::vec3> lightSh_;  ///< ShTransfer: Σ lights' SH coefficients, (order)²
};

/// Where a bake takes each vertex's irradiance from.
enum class BakeSource {
    /// Paths traced from the vertex itself on the mesh's isosurface (IlluminationLattice::
    /// pointIrradiance with the lattice's options): the reference, and the default of
    /// `voxlight iso --bake`. bench_lattice: NRMS 0.03 at 100 paths against 10,000.
    Vertices,
    /// Trilinear from the lattice (Wyman): texels computed once serve every isovalue and light
    /// change (SH), but on sharp-edged data the texels around a vertex lie on other isosurfaces:
    /// bench_lattice NRMS 0.39 (torso) and 0.48 (abdominal CT) whatever the paths.
    Lattice,
};

/// Bakes light into the mesh's vertex colours (the lit-mesh export; the mesh is the isosurface at
/// `isovalue`, physical): colour = albedo ⊙ E(vertex)/π · scale — the radiance a Lambertian
/// surface of that albedo leaves, linear RGB (exporters clamp to [0, 1] and encode,
/// iso/export.h); `scale` is the display exposure, 2^stops. E from `source`. Returns the stats
/// (for Vertices: paths and seconds only). `transfer` (Lattice source, ShTransfer lattice only):
/// also each vertex's interpolated transfer vector, [(vertex · order² + i) · 3 + channel].
LatticeStats bakeVertexColours(Mesh& mesh, IlluminationLattice& lattice, double isovalue,
                               const glm::vec3& albedo, float scale, BakeSource source,
                               const core::Progress& progress = core::Progress::none(),
                               std::vector<float>* transfer = nullptr);

}  // namespace voxlight::iso
