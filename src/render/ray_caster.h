// SPDX-License-Identifier: MIT
#pragma once
// The CPU ray caster: front-to-back compositing of the optical model of ARCHITECTURE.md §1 along
// camera rays through a scalar volume, with empty-space skipping on the brick grid, early ray
// termination, jittered (deterministic per pixel) ray starts, clip planes and a crop box, and
// oneTBB tiles. Every pixel is a pure function of (scene, pixel, seed): images are identical for
// any thread count.
//
// Modes:
//   EmissionAbsorption  σt / albedo / emission from the TF, uniform unit illumination, no
//                       visibility
//   Gradient            gradient Blinn–Phong, directional and point lights (the clinical baseline)
//   Mip / MinIp         maximum / minimum value along the ray, shown as grey through the window
//   Isosurface          direct isosurface (Ritschel's DIR): first crossing of the isovalue along
//                       the ray, refined by bisection, Lambertian with the TF albedo at the
//                       isovalue
//
// Sampling: the step is Δ = stepVoxels · (smallest voxel spacing) mm. Sample points along a ray
// are t_0 = tNear (exactly on the entry plane/box), then tNear + (j + k)·Δ with the per-pixel
// jitter j ∈ [0, 1), and finally tFar (exactly on the exit) — partial end segments are integrated
// with their true length, so there is no staircase at clip planes. A segment between two samples
// has opacity α = 1 − exp(−τ) with τ = Δ_segment · mean σt (pre-integrated over the two values, or
// the midpoint value when pre-integration is off).
//
// Clipping: the kept region is the intersection of the half-spaces dot(x − p, n) ≥ 0 and the crop
// box. Where a ray enters through a clip plane or crop face, samples within kClipFaceBandVoxels of
// the entry are shaded with the plane's normal where the gradient is weak (the cut face of a
// homogeneous organ), as clinical viewers do. A plane or crop face on the volume box's own entry
// face (up to rounding) removes nothing there and is no cut face.
//
// Output: core::ImageRGBA with *linear* radiance + T·background in RGB and coverage 1 − T in alpha.
// Non-finite voxels never produce non-finite pixels (NaN samples act as the TF's lowest value).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/progress.h"
#include "core/volume.h"
#include "grid/brick_grid.h"
#include "grid/brick_traversal.h"
#include "lights/light.h"
#include "optics/transfer_function.h"
#include "render/camera.h"
#include "render/shading.h"

namespace voxlight::render {

enum class Mode { EmissionAbsorption, Gradient, Mip, MinIp, Isosurface };
std::string toString(Mode m);

/// Camera rays never see what a clip plane or the crop box removes. Whether the *light* still
/// does is `shadowsFromRemoved` (io/scene.h): true = section view, the removed matter keeps
/// occluding light; false = it is gone for the light too. The ray caster's own modes cast no
/// shadow rays, so it reads only the geometry; the path tracer and the SH methods' visibility
/// (pipeline) read the flag.
struct ClipPlane {
    glm::dvec3 point{0.0};
    glm::dvec3 normal{0.0, 0.0, 1.0};  ///< unit; keeps dot(x − point, normal) ≥ 0
    bool shadowsFromRemoved = false;
};
struct CropBox {
    glm::dvec3 min{0.0}, max{0.0};  ///< world mm, axis-aligned
    bool shadowsFromRemoved = false;
};

/// Transmittance below which a ray stops: what is behind contributes < 0.1 % (below one 8-bit
/// display level).
inline constexpr float kTerminationTransmittance = 1e-3f;
/// Depth (in units of the smallest voxel spacing) behind a clip entry where the plane normal
/// replaces a weak gradient.
inline constexpr float kClipFaceBandVoxels = 2.f;
/// A gradient weaker than this fraction of the TF window width per mm counts as "weak": its
/// normal is blended toward the fallback (plane normal at a cut face, else the view direction).
inline constexpr float kWeakGradientFraction = 0.01f;
/// Side (voxels) of the majorant cells the ray caster skips with: the 16³ bricks are refined to
/// 4³ cells inside the bricks the TF does not make transparent (a scan of those bricks only), so
/// thin structures (ribs, vessels) do not force sampling of the soft tissue around them. Empty
/// stretches are crossed in skip-distance jumps (grid::forEachNonEmptyRun), so the finer cells do
/// not cost DDA steps there (measured: 4³ with jumps 12 % (torso) and 24 % (bonsai) faster per
/// frame than 8³ cells stepped one by one).
inline constexpr int kSkipCellVoxels = 4;
/// Largest image the renderer accepts (pixels): 16384 × 8192 RGBA float is 2 GiB.
inline constexpr std::uint64_t kMaxPixels = std::uint64_t(16384) * 8192;
/// InputError ("render options", "image size") for an image past kMaxPixels: what render()
/// refuses, for callers that check before their own work (the viewer, before a window opens).
void checkImageSize(int width, int height);

/// Which central-difference table the gradient mode uses.
enum class GradientTable {
    Auto,     ///< dense up to VoxelGradients::kMaxVoxels voxels, bricked beyond
    Dense,    ///< VoxelGradients (when the volume is at most kMaxVoxels)
    Bricked,  ///< BrickedGradients
};

struct RenderOptions {
    Mode mode = Mode::Gradient;
    float stepVoxels = 0.5f;    ///< step in units of the smallest voxel spacing, > 0
    bool preintegrated = true;  ///< pre-integrated segments (else midpoint point sampling)
    bool emptySpaceSkipping = true;
    /// With emptySpaceSkipping: pixels outside the projection of the non-empty cells
    /// (PixelFootprint) get the background without a ray. Off only to measure or test it.
    bool pixelFootprint = true;
    bool earlyTermination = true;
    /// Rays stop once their transmittance falls below this (with earlyTermination), ∈ [0, 1).
    float terminationTransmittance = kTerminationTransmittance;
    bool jitter = true;  ///< per-pixel deterministic start offset
    std::uint64_t seed = 1;
    int threads = 0;            ///< 0 = all hardware threads
    glm::vec3 background{0.f};  ///< linear RGB behind the volume
    std::vector<ClipPlane> clipPlanes;
    std::optional<CropBox> cropBox;
    /// Gradient/Isosurface lights (see BlinnPhongShader for how each type shades); empty = one
    /// headlight.
    std::vector<std::shared_ptr<const lights::Light>> lights;
    /// environmentIrradianceSh(lights): required when an environment light is among them.
    std::vector<glm::vec3> irradianceSh;
    BlinnPhongParams blinnPhong;  ///< Gradient (Isosurface uses ambient + diffuse only)
    float ambient = 1.f;          ///< EmissionAbsorption: uniform illumination
    /// Gradient normals by central differences (6 taps) or forward differences (3 taps, faster).
    bool centralDifferences = true;
    /// Table of the central differences (with centralDifferences in Gradient mode).
    GradientTable gradientTable = GradientTable::Auto;
    std::optional<float> isoValue;  ///< Isosurface: physical value; default TF surfaceValue()
    int tileSize = 16;              ///< pixels per tile side
    /// SH visibility shading (render/sh_shading.h): band factors w_0..w_L applied to the lights'
    /// coefficients (sh/sh_window.h windowFactors; w_0 = 1); empty = no window.
    std::vector<double> shWindow;
    /// SH visibility shading: radiance of a uniform white sky added to the lights, shadowed by the
    /// same visibility (ambient occlusion: A·V_0/√(4π), A in empty space); 0 = none.
    float shAmbient = 0.f;
    /// sh-local: trace each delta light's first stretch exactly where the field is coarse
    /// (render/sh_shading.h ShLocalShader; method param `near_shadow`).
    bool shNearShadow = false;
    /// With shNearShadow: voxels traced at every level on top of ½·(s − 1) (method param
    /// `near_trace`; render/sh_shading.h kNearShadowSpacings).
    float shNearTraceVoxels = 0.f;
};

struct RenderStats {
    std::uint64_t rays = 0;             ///< rays that hit the (clipped) volume
    std::uint64_t samples = 0;          ///< volume samples taken (incl. gradient taps)
    std::uint64_t terminatedEarly = 0;  ///< rays stopped by early termination
    /// kSkipCellVoxels³ skip cells, and those not empty under the current TF / mode.
    std::size_t skipCells = 0, skipCellsVisible = 0;
};

class RayCaster;
struct VoxelGradients;
struct BrickedGradients;

/// The precomputed tables a caster reads. Each depends on a known subset of the inputs, so the
/// pipeline builds it as one stage's artifact and shares it between frames and casters:
///   table            ← TF
///   skipCells        ← volume + TF + the mode's skip rule (iso value for Isosurface)
///   voxelGradients   ← volume
///   brickedGradients ← volume + skipCells
struct CasterTables {
    std::shared_ptr<const optics::TfTable> table;
    std::shared_ptr<const grid::BrickMajorants> skipCells;
    std::shared_ptr<const VoxelGradients> voxelGradients;      ///< may be null
    std::shared_ptr<const BrickedGradients> brickedGradients;  ///< may be null
};

/// The isovalue the Isosurface mode uses: options.isoValue, else the TF's surfaceValue().
/// Throws InputError (field "iso_value") when it is not finite.
float resolveIsoValue(const optics::TransferFunction& tf, const RenderOptions& options);

/// The kSkipCellVoxels³ skip cells of `options.mode` (the 16³ bricks classified, then refined
/// inside the bricks that are not empty): DVR modes skip where the TF's σt is 0 over the cell's
/// value range (widened by one table cell), MIP/MinIP skip nothing but keep the cells' value
/// ranges, Isosurface skips cells whose range does not hold the isovalue.
grid::BrickMajorants buildSkipCells(const core::Volume& volume, const grid::BrickGrid& grid,
                                    const optics::TransferFunction& tf,
                                    const optics::TfTable& table, const RenderOptions& options);

/// Which central-difference table a caster with these options reads.
enum class GradientTableUse { None, Dense, Bricked };
GradientTableUse gradientTableUse(const core::Volume& volume, const RenderOptions& options);
/// The same from the voxel count alone (what the choice depends on).
GradientTableUse gradientTableUse(std::uint64_t voxelCount, const RenderOptions& options);

/// Per-voxel central differences of the *stored* voxel values, D(i,j,k) = (v[i+1] − v[i−1],
/// v[j+1] − v[j−1], v[k+1] − v[k−1]) with indices clamped to the grid, kept as int16 (exact for
/// integer volumes whose differences fit). Trilinear interpolation is linear in the data, so
/// interpolating D at p equals the central difference of the trilinear field at p ± 1 voxel
/// (gradientAt) up to float rounding, including the clamping at the edges: one 8-corner fetch
/// instead of six trilinear taps, computed once per caster (VTK encodes normals the same way,
/// but quantised). Two layouts with one interface (corner()): VoxelGradients, dense on the
/// volume's own grid (its index is the value sample's, so a fetch costs no index arithmetic;
/// 8 bytes per voxel), and BrickedGradients, only near the visible cells (for volumes too large
/// for the dense table).
using GradientEntry = std::array<std::int16_t, 4>;  ///< (Δi, Δj, Δk, 0)

struct VoxelGradients {
    /// Largest volume (voxels) that gets the dense table (GradientTable::Auto): 512 MiB.
    static constexpr std::uint64_t kMaxVoxels = std::uint64_t(1) << 26;
    std::vector<GradientEntry> d;        ///< per voxel, x fastest
    std::size_t di = 0, dj = 0, dk = 0;  ///< corner strides (0 on a single-voxel axis)
    float slope = 1.f;                   ///< stored → physical value
    /// The table for `volume`, or empty when the type is float or a difference does not fit.
    /// Throws CancelledError when `progress` is cancelled (checked per slice).
    static VoxelGradients build(const core::Volume& volume,
                                const core::Progress& progress = core::Progress::none());
    bool empty() const { return d.empty(); }
    /// Looked up by the cell's linear voxel index (cell.offset), not by (i, j, k).
    static constexpr bool kByIndex = false;
    /// Entry of the lower corner of a located cell (cell.offset: its linear voxel index).
    template <class Cell>
    const GradientEntry* corner(const Cell& cell) const {
        return d.data() + cell.offset;
    }
};

/// The central differences only where shading can ask for them: in the kBrickVoxels³ bricks that
/// hold a skip cell within one cell of a non-empty one (a shaded segment ends at most one step
/// past a non-empty cell at steps up to a cell), each stored with a one-voxel apron on its high
/// sides, so that the 8 corners of any cell whose lower corner is in the brick lie in its
/// kStored³ block. Elsewhere corner() is null and the marcher takes the six-tap central
/// difference of the field (the same values up to rounding). Built per transfer function.
struct BrickedGradients {
    static constexpr int kBrickVoxels = 16;
    static constexpr int kStored = kBrickVoxels + 1;
    static constexpr std::size_t kBrickEntries = std::size_t(kStored) * kStored * kStored;
    /// Most entries (8 bytes each) the table may hold (1 GiB): bricks with a non-empty cell
    /// come first, then their neighbours; bricks beyond the limit are not stored.
    static constexpr std::uint64_t kMaxEntries = std::uint64_t(1) << 27;
    std::vector<std::int64_t> slot;  ///< per brick (i fastest): its first entry in d, or −1
    std::vector<GradientEntry> d;
    glm::ivec3 bricks{0};
    std::size_t di = 0, dj = 0, dk = 0;  ///< corner strides in a block (0 on a single-voxel axis)
    float slope = 1.f;                   ///< stored → physical value
    /// The table for `volume` in the bricks near the non-empty cells of `cells` (the caster's
    /// kSkipCellVoxels³ skip cells, with skip distances); empty when the type is float or a
    /// difference does not fit in int16. Throws CancelledError when `progress` is cancelled
    /// (checked per brick).
    static BrickedGradients build(const core::Volume& volume, const grid::BrickMajorants& cells,
                                  std::uint64_t maxEntries = kMaxEntries,
                                  const core::Progress& progress = core::Progress::none());
    bool empty() const { return d.empty(); }
    /// Looked up by the cell's lower corner (cell.i, cell.j, cell.k).
    static constexpr bool kByIndex = true;
    /// Entry of a located cell's lower corner (i, j, k) in its brick's block, with the other
    /// corners at +di, +dj, +dk; null when the brick is not stored.
    template <class Cell>
    const GradientEntry* corner(const Cell& cell) const {
        static_assert(kBrickVoxels == 16, "shifts and masks below");
        const auto ui = unsigned(cell.i), uj = unsigned(cell.j), uk = unsigned(cell.k);
        const std::int64_t s =
            slot[(ui >> 4) + std::size_t(bricks.x) *
                                 ((uj >> 4) + std::size_t(bricks.y) * std::size_t(uk >> 4))];
        if (s < 0) return nullptr;
        return d.data() + s + (ui & 15u) +
               std::size_t(kStored) * ((uj & 15u) + std::size_t(kStored) * (uk & 15u));
    }
};

/// The per-tile seam between traversal and shading: one virtual call per tile, concrete shader
/// types inside (see shading.h). The built-in modes are ShadingModels too.
class ShadingModel {
  public:
    virtual ~ShadingModel() = default;
    virtual std::string name() const = 0;
    /// Renders pixels [x0, x1) × [y0, y1) into `film`. Called concurrently for disjoint tiles.
    virtual void renderTile(const RayCaster& caster, const Camera& camera, int x0, int y0, int x1,
                            int y1, core::ImageRGBA& film, RenderStats& stats) const = 0;
};

/// visibleRange() widens the non-empty cells' box by this much on each side (voxels), so that float
/// rounding of the clipped ends can never cut a sample off a non-empty cell; beyond the margin
/// there are only empty cells.
inline constexpr float kVisibleBoxMarginVoxels = 0.01f;

/// Ray set-up shared by every model: the clipped parametric range of one camera ray.
struct RaySegment {
    glm::vec3 originWorld, dirWorld;  ///< world mm (float copies for the hot loop)
    glm::vec3 originIndex, dirIndex;  ///< continuous index space, per mm of t
    float tNear = 0.f, tFar = 0.f;    ///< mm along the ray
    float jitter = 0.f;               ///< ∈ [0, 1)
    bool clipEntry = false;           ///< entered through a clip plane or crop face
    glm::vec3 entryNormal{0.f};       ///< outward normal of that face (facing the eye)
    bool hit() const { return tFar > tNear; }
};

class RayCaster {
  public:
    /// From tables built beforehand (pipeline stages: each is an owned, shareable artifact).
    /// `tables` must hold the TF table and skip cells for these options (buildSkipCells), and the
    /// gradient table gradientTableUse() names (else the marcher's six-tap fallback is used).
    /// Throws InputError on bad options (step ≤ 0, ...).
    RayCaster(std::shared_ptr<const core::Volume> volume,
              std::shared_ptr<const optics::TransferFunction> tf, RenderOptions options,
              CasterTables tables);
    /// Builds every table itself (tests, benchmarks). The volume and TF must outlive the caster.
    RayCaster(const core::Volume& volume, const grid::BrickGrid& grid,
              const optics::TransferFunction& tf, RenderOptions options);

    /// Renders with the built-in model of options().mode.
    core::ImageRGBA render(const Camera& camera,
                           const core::Progress& progress = core::Progress::none(),
                           RenderStats* stats = nullptr) const;
    /// Renders with any shading model (later issues plug theirs in here).
    core::ImageRGBA render(const Camera& camera, const ShadingModel& model,
                           const core::Progress& progress = core::Progress::none(),
                           RenderStats* stats = nullptr) const;

    /// The clipped range of the camera ray through pixel (x, y).
    RaySegment setupRay(const Camera& camera, int x, int y) const;

    const core::Volume& volume() const { return *volume_; }
    const optics::TransferFunction& transferFunction() const { return *tf_; }
    const optics::TfTable& table() const { return *tables_.table; }
    std::shared_ptr<const optics::TfTable> tablePtr() const { return tables_.table; }
    const grid::BrickMajorants& majorants() const { return *tables_.skipCells; }
    const RenderOptions& options() const { return options_; }
    float stepMm() const { return stepMm_; }
    float isoValue() const { return isoValue_; }
    /// Gradient (value/mm, world) from central differences = gradientMatrix · (Δi, Δj, Δk).
    const glm::mat3& gradientMatrix() const { return gradientMatrix_; }
    float weakGradient() const { return weakGradient_; }
    /// The part [t0, t1] of the ray's [tNear, tFar] inside the index-space box of the non-empty
    /// skip cells (extended to the volume box where it reaches the grid's edge, then widened by
    /// kVisibleBoxMarginVoxels); false when the ray misses it or nothing is visible. Every
    /// non-empty run lies inside, so traversal may start and stop there.
    bool visibleRange(const RaySegment& r, float& t0, float& t1) const;
    /// The volume box in index space, where rays run: the voxel centres [0, n − 1] per axis, ±0.5
    /// on an axis with a single slice.
    std::array<glm::dvec3, 2> volumeIndexBox() const { return {indexBoxLo_, indexBoxHi_}; }
    /// Index-space bounds of the non-empty skip cells (cell edges, clamped to the voxel-centre
    /// box); empty (lo > hi) when no cell is non-empty.
    const std::array<glm::vec3, 2>& visibleIndexBox() const { return visibleIndexBox_; }
    /// Precomputed central differences (Gradient mode with central differences), or nullptr.
    const VoxelGradients* voxelGradients() const {
        const auto& g = tables_.voxelGradients;
        return g && !g->empty() ? g.get() : nullptr;
    }
    /// Bricked central differences (Gradient mode, large volumes), or nullptr.
    const BrickedGradients* brickedGradients() const {
        const auto& g = tables_.brickedGradients;
        return g && !g->empty() ? g.get() : nullptr;
    }

  private:
    std::shared_ptr<const core::Volume> volume_;
    std::shared_ptr<const optics::TransferFunction> tf_;
    CasterTables tables_;
    RenderOptions options_;
    float stepMm_ = 1.f, isoValue_ = 0.f, weakGradient_ = 1.f;
    glm::dvec3 indexBoxLo_{0.0}, indexBoxHi_{0.0};  ///< the volume box in index space
    std::array<glm::vec3, 2> visibleIndexBox_{glm::vec3(0.f), glm::vec3(-1.f)};
    std::array<glm::vec3, 2> clipBox_{glm::vec3(0.f), glm::vec3(-1.f)};  ///< visibleRange's box
    glm::mat3 gradientMatrix_{1.f};
    glm::dmat3 worldToIndexMatrix_{1.0};  ///< diag(1/spacing) · directionᵀ
};

/// World-space axis-aligned bounds of what the caster can see (the non-empty skip cells; the
/// whole volume when nothing or everything is skippable): cameras fit this, so a TF that shows
/// only the skeleton frames the skeleton rather than the air around the patient.
std::array<glm::dvec3, 2> visibleWorldBounds(const RayCaster& caster);
/// The same from the geometry and the skip cells alone (what a fitted camera depends on).
std::array<glm::dvec3, 2> visibleWorldBounds(const core::Geometry& geometry,
                                             const grid::BrickMajorants& skipCells);

/// Built-in shading model of options().mode; with no lights given, Gradient/Isosurface get one
/// directional light from just above-left of the camera (a head light, as clinical viewers use).
std::unique_ptr<ShadingModel> makeBuiltinModel(const RayCaster& caster, const Camera& camera);

}  // namespace voxlight::render
