// SPDX-License-Identifier: MIT
// The CPU ray caster's methods (render/ray_caster.h): emission-absorption, gradient, mip, minip,
// iso, and the SH visibility methods sh-local, sh-global, ritschel. One module: their params, their stages and their codecs. Params (all optional; unknown keys
// are an InputError naming the allowed ones):
//   every method:         step (voxels; default render.step), preintegrated, empty_space_skipping,
//                         early_termination, jitter (booleans)
//   emission-absorption:  ambient
//   gradient:             ambient, diffuse, specular, shininess, central_differences (true: 6-tap
//                         gradients from a table; false: 3-tap forward differences, no table)
//   iso:                  iso_value (physical; default where the TF reaches 1/10 of its max σt),
//                         ambient, diffuse
//   mip, minip:           (window from the TF)
//   sh-local:             rays (32), coefficients (1/4/9/16; 4), radius (voxels; 16), and the LOD
//                         budget as data_reduction (voxels per grid sample; 8) or lod_budget_mb
//                         (MB of visibility coefficients; not both); near_shadow (true: each
//                         directional/point light's, and an environment map's dominant
//                         direction's, first ½·(s − 1) voxels traced exactly where the field is
//                         stored at spacing s — render/sh_shading.h ShLocalShader)
//                         and near_trace (voxels traced at every level on top of that; 0)
//   sh-global:            the same + global_resolution (grid points per axis; 64, capped at the
//                         volume's dims) and global_near ("local": the fine local field at the
//                         sample times the far grid, default; "grid": Kronander's grid-only V^G —
//                         visibility/global_visibility.h) and global_integration ("recursive":
//                         one piece per grid point and direction, the rest read back from the
//                         grid, default; "piecewise": eq. 11 along every ray); near_shadow
//                         and near_trace read its near factor as sh-local's do (ShGlobalShader;
//                         with global_near "local" only). Its local stages have the same keys as
//                         sh-local's, so switching between the two recomputes nothing once both
//                         have run.
//   ritschel:             hierarchical visibility (Ritschel 2007; visibility/
//                         hierarchical_visibility.h): rays (32), coefficients (1/4/9/16; 4),
//                         patterns (M jittered direction sets; 16), subsample (1:s grid, 1…8;
//                         2), quantize_8bit (false), max_distance (voxels; absent = to the
//                         volume's boundary: growing steps make the far part cheap),
//                         hierarchical (true; false = 1-voxel steps on level 0, the brute-force
//                         reference). Stages opacity_pyramid ← block_pyramid + TF and
//                         hierarchical_visibility ← opacity_pyramid + these params (+ seed), or
//                         clip_hierarchical_visibility ← the same + the planes that remove matter
//                         for the light (see below).
//   pathtrace:            spp (64; the most when a target error is set), seconds, target_error
//                         (relative NRMS the samples predict; 0 = off), reference (false; true:
//                         pixel-centre samples, target_error 0.01, up to 16384 spp, and the image
//                         becomes the cached `reference` stage), max_bounces (1, or 16 with the
//                         multiple_scattering effect), phase_g (a TF's phase_g channel
//                         overrides it), scattering ("phase" | "brdf" | "hybrid"; "phase") and
//                         gradient_factor (hybrid only; 0.5: Kroes' g_f, path_tracer.h),
//                         majorant_grid, antialias, adaptive (true unless reference: each
//                         pass's samples shared by the pixels' noise, path_tracer.h; never
//                         with reference),
//                         denoise (true | false | "auto" = on unless reference; never in
//                         reference mode: true there is an error) and denoise_target (0.01: the
//                         relative standard error at and below which a pixel is left as traced;
//                         pathtrace/denoise.h). The denoised image is the display (PNG) only: the
//                         main image (EXR, sweeps) and the std_error image stay the raw estimate.
// Clip planes and the crop box (io/scene.h shadows_from_removed): camera rays never see removed
// matter in any method. The ray caster's own modes cast no shadow rays; the path tracer reads each
// plane's choice itself (pathtrace/path_tracer.h). sh-local/sh-global: the unclipped local
// visibility stays cached; planes (and the box) with shadows_from_removed false add the stage
// clip_local_visibility (visibility/local_visibility.h: only the points within r_s of such a face
// are traced again), and sh-global's global stage then integrates that field. Both keys cover the
// removing planes only, so a section-view plane (true), or moving one, reruns no visibility stage.
// sh-global shades from local visibility near the faces that remove matter for the light
// (render/sh_shading.h ShGlobalShader, within one global grid spacing). ritschel: the same
// planes add clip_hierarchical_visibility in place of hierarchical_visibility (visibility/
// hierarchical_visibility.h: the removed matter zeroed at the opacity pyramid's base, the rays
// traced again — they reach the whole volume, so a move of such a plane retraces the field's kept
// side, not a slab); its key covers the removing planes only, as above.
// Lights: gradient and iso shade with every light type (render/shading.h says how); sh-local,
// sh-global and ritschel with directional, point and environment lights (render/sh_shading.h);
// the other three are unlit, so their plans mark the light stages "not needed". Effects: gradient
// simulates "specular" (an effects list without it turns the highlight off); sh-global and
// ritschel local_shadows and global_shadows, sh-local local_shadows.
#include <cmath>
#include <map>
#include <optional>
#include <sstream>

#include "core/hash.h"
#include "core/rng.h"
#include "core/timing.h"
#include "grid/brick_grid.h"
#include "grid/brick_traversal.h"
#include "iso/lattice.h"
#include "lights/environment_light.h"
#include "optics/presets.h"
#include "pathtrace/path_tracer.h"
#include "pipeline/iso_shading.h"
#include "pipeline/registry.h"
#include "pipeline/scene_inputs.h"
#include "pvrt/basis.h"
#include "pvrt/cpca.h"
#include "pvrt/direct.h"
#include "pvrt/photons.h"
#include "pvrt/radiance.h"
#include "pvrt/transfer.h"
#include "render/framing.h"
#include "render/ray_caster.h"
#include "render/sh_shading.h"
#include "sh/sh_basis.h"
#include "sh/sh_window.h"
#include "visibility/global_visibility.h"
#include "visibility/hierarchical_visibility.h"
#include "visibility/local_visibility.h"

namespace voxlight::pipeline {

namespace {

using nlohmann::json;

// ---- Artifacts -----------------------------------------------------------------------------

struct LoadedVolume {
    /// `data` loaded (or adopted: adoptVolume) for the scene; `volume` refers to it.
    explicit LoadedVolume(std::shared_ptr<const core::Volume> v)
        : data(std::move(v)),
          volume(*data),
          contentHash(core::contentHash(volume)),
          nonFinite(volume.countNonFinite()) {}
    std::shared_ptr<const core::Volume> data;
    const core::Volume& volume;
    std::uint64_t contentHash = 0;
    std::uint64_t nonFinite = 0;
};

struct TfArtifact {
    optics::TransferFunction tf;
    std::shared_ptr<const optics::TfTable> table;
};

struct GradientArtifact {
    std::shared_ptr<const render::VoxelGradients> dense;
    std::shared_ptr<const render::BrickedGradients> bricked;
};

using LightList = std::vector<std::shared_ptr<const lights::Light>>;

// Bytes per artifact, for the memory budget: a skip cell holds a majorant, a value range, a flag
// and a skip distance; a TF table holds kTableCells + 1 nodes of σt, albedo and emission plus the
// pre-integration sums (~16 floats each).
constexpr std::size_t kSkipCellBytes = 4 + 8 + 1 + 1;
constexpr std::size_t kTfBytes = sizeof(TfArtifact) + (optics::TfTable::kTableCells + 1) * 16 * 4;

/// The lights as held in memory (an environment map keeps its texels, CDFs and SH).
std::size_t lightBytes(const LightList& lights) {
    std::size_t bytes = 0;
    for (const auto& l : lights) {
        bytes += 256;
        if (const auto* e = dynamic_cast<const lights::EnvironmentLight*>(l.get()))
            bytes += std::size_t(e->width()) * e->height() * (12 + 8 + 8);
    }
    return bytes;
}

/// Version of what the transfer_function stage computes beyond its inputs (robust range, default
/// preset per modality): bump when that code changes. The presets' own definitions are hashed.
constexpr std::uint32_t kTfStageVersion = 2;

/// Bounces per path when multiple scattering is asked for (Russian roulette ends most before).
constexpr int kDefaultMaxBounces = 16;

/// A volume whose lowest value is above this holds no air in HU (air −1000, fat −100): a CT preset
/// on it is a mistake worth a warning.
constexpr float kNoAirAbove = -200.f;

/// A hash of every preset's definition in this build (points on the unit range), so a retuned
/// preset never meets a TF cached by an older build.
std::uint64_t presetCatalogHash() {
    static const std::uint64_t h = [] {
        core::Hasher hh;
        for (const auto& p : optics::presetCatalog()) {
            const optics::TransferFunction tf = optics::makePreset(p.name, {0.f, 1.f});
            hh.add(p.name).add(p.relative);
            for (const auto& pt : tf.points()) hh.addPod(pt);
            hh.addPod(tf.window());
        }
        return hh.value();
    }();
    return h;
}

// ---- Codecs (bump a version when its encoding or meaning changes) ---------------------------

/// Sizes a cache file may claim (far above any volume the readers accept).
constexpr std::uint64_t kMaxCells = std::uint64_t(1) << 34;

[[noreturn]] void badPayload(const std::string& what) { throw CacheFormatError(what); }

const Codec& brickGridCodec() {
    static const Codec c{1,
                         [](const Artifact& a, ByteWriter& w) {
                             const auto& g = *a.as<grid::BrickGrid>();
                             w.pod(g.dims());
                             w.pod(g.valueLo());
                             w.pod(g.valueHi());
                             w.array(g.bricks());
                         },
                         [](ByteReader& r) {
                             const auto dims = r.pod<glm::ivec3>();
                             const auto lo = r.pod<float>(), hi = r.pod<float>();
                             auto bricks = r.array<grid::BrickStats>(kMaxCells);
                             auto g = std::make_shared<grid::BrickGrid>();
                             if (!grid::BrickGrid::fromParts(dims, lo, hi, std::move(bricks), *g))
                                 badPayload("brick grid parts do not fit together");
                             const std::size_t bytes = g->size() * sizeof(grid::BrickStats);
                             return Artifact::of<grid::BrickGrid>(std::move(g), bytes);
                         }};
    return c;
}

const Codec& skipCellsCodec() {
    static const Codec c{
        1,
        [](const Artifact& a, ByteWriter& w) {
            const auto& m = *a.as<grid::BrickMajorants>();
            w.pod(m.counts());
            w.pod(m.cellSize());
            std::vector<float> maj(m.size());
            std::vector<std::array<float, 2>> ranges(m.size());
            for (std::size_t i = 0; i < m.size(); ++i) {
                maj[i] = m.majorant(i);
                ranges[i] = m.valueRange(i);
            }
            w.array(maj);
            w.array(ranges);
        },
        [](ByteReader& r) {
            const auto counts = r.pod<glm::ivec3>();
            const int cellSize = r.pod<int>();
            auto maj = r.array<float>(kMaxCells);
            auto ranges = r.array<std::array<float, 2>>(kMaxCells);
            constexpr int kMaxCount = core::kMaxDim / render::kSkipCellVoxels + 1;
            if (counts.x < 1 || counts.y < 1 || counts.z < 1 || counts.x > kMaxCount ||
                counts.y > kMaxCount || counts.z > kMaxCount ||
                cellSize != render::kSkipCellVoxels ||
                maj.size() != std::size_t(counts.x) * counts.y * counts.z ||
                ranges.size() != maj.size())
                badPayload("skip cell sizes do not fit together");
            for (float m : maj)
                if (!(m >= 0.f)) badPayload("negative or NaN majorant");
            const std::size_t bytes = maj.size() * kSkipCellBytes;
            return Artifact::of(
                std::make_shared<const grid::BrickMajorants>(grid::BrickMajorants::fromCells(
                    counts, cellSize, std::move(maj), std::move(ranges))),
                bytes);
        }};
    return c;
}

const Codec& transferFunctionCodec() {
    // 2: TfPoint gained the surface channels (specular, roughness, phase g).
    static const Codec c{2,
                         [](const Artifact& a, ByteWriter& w) {
                             const auto& t = a.as<TfArtifact>()->tf;
                             w.string(t.name());
                             w.pod(t.window());
                             w.array(t.points());
                         },
                         [](ByteReader& r) {
                             auto t = std::make_shared<TfArtifact>();
                             const std::string name = r.string(256);
                             const auto window = r.pod<optics::Window>();
                             auto points = r.array<optics::TfPoint>(1 << 20);
                             // The constructor validates the points (InputError → the cache reports and recomputes).
                             t->tf = optics::TransferFunction(std::move(points), window, name);
                             t->table = std::make_shared<const optics::TfTable>(t->tf);
                             return Artifact::of<TfArtifact>(std::move(t), kTfBytes);
                         }};
    return c;
}

const Codec& irradianceCodec() {
    static const Codec c{
        1, [](const Artifact& a, ByteWriter& w) { w.array(*a.as<std::vector<glm::vec3>>()); },
        [](ByteReader& r) {
            auto v = std::make_shared<std::vector<glm::vec3>>(r.array<glm::vec3>(9));
            if (!v->empty() && v->size() != 9) badPayload("irradiance SH needs 9 coefficients");
            return Artifact::of<std::vector<glm::vec3>>(std::move(v), 9 * 12);
        }};
    return c;
}

// ---- Method params -------------------------------------------------------------------------

enum class Kind {
    EmissionAbsorption,
    Gradient,
    Mip,
    MinIp,
    Iso,
    IsoLattice,
    ShLocal,
    ShGlobal,
    Ritschel,
    PathTrace,
    Pvrt
};

render::Mode modeOf(Kind k) {
    switch (k) {
        case Kind::EmissionAbsorption:
        case Kind::PathTrace:  // its skip cells are the σt majorants of delta tracking
            return render::Mode::EmissionAbsorption;
        case Kind::Gradient:
            return render::Mode::Gradient;
        case Kind::Mip:
            return render::Mode::Mip;
        case Kind::MinIp:
            return render::Mode::MinIp;
        case Kind::Iso:
        case Kind::IsoLattice:
            return render::Mode::Isosurface;
        case Kind::ShLocal:  // DVR traversal and skip rule; shading by render/sh_shading.h
        case Kind::ShGlobal:
        case Kind::Ritschel:
        case Kind::Pvrt:  // DVR traversal; shading from the radiance volume (pvrt/radiance.h)
            return render::Mode::EmissionAbsorption;
    }
    throw InternalError("unknown ray-caster method");
}

/// Methods shaded by an SH visibility field (render/sh_shading.h).
bool isSh(Kind k) { return k == Kind::ShLocal || k == Kind::ShGlobal || k == Kind::Ritschel; }
/// The two on Kronander's multiresolution grid.
bool isKronander(Kind k) { return k == Kind::ShLocal || k == Kind::ShGlobal; }
bool isLit(Kind k) {
    return k == Kind::Gradient || k == Kind::Iso || k == Kind::IsoLattice || isSh(k) ||
           k == Kind::PathTrace || k == Kind::Pvrt;
}

/// sh-local's and sh-global's own parameters (see the header comment).
struct ShParams {
    visibility::LocalVisibilityOptions visibility;
    visibility::GlobalVisibilityOptions global;  ///< sh-global
    double dataReduction = 8.0;
    double budgetMb = 0.0;  ///< > 0: the budget in MB instead of dataReduction
    visibility::LodBudget budget(std::uint64_t voxels) const {
        return budgetMb > 0.0 ? visibility::LodBudget::fromBytes(budgetMb * 1048576.0,
                                                                 4.0 * visibility.coefficients)
                              : visibility::LodBudget::fromReduction(dataReduction, voxels);
    }
    nlohmann::json budgetKey() const {
        return budgetMb > 0.0 ? nlohmann::json{{"lod_budget_mb", budgetMb}}
                              : nlohmann::json{{"data_reduction", dataReduction}};
    }
};

ShParams parseShParams(Kind kind, const io::Scene& scene, ParamReader& p) {
    ShParams s;
    s.visibility.coefficients = p.integer("coefficients", 4, 1, 16);
    const int c = s.visibility.coefficients;
    if (c != 1 && c != 4 && c != 9 && c != 16)
        p.fail("coefficients", "must be 1, 4, 9 or 16, got " + std::to_string(c),
               "1 is ambient occlusion; 4, 9, 16 are SH bands 1, 2, 3");
    // The line sweep by default (more accurate than the march at every LOD level and several
    // times faster); the march when `rays` asks for a count the sweep's lattice cannot give.
    const int minRays = visibility::kMinRaysPerCoefficient * c;
    const bool raysGiven = p.has("rays");
    const int rays = raysGiven ? p.integer("rays", 0, minRays, 4096) : 0;
    const bool latticeRays =
        !raysGiven || rays == visibility::kSweepRaysCoarse || rays == visibility::kSweepRaysFine;
    const bool sweep =
        p.choice("algorithm", latticeRays ? "sweep" : "march", {"march", "sweep"}) == "sweep";
    s.visibility.algorithm =
        sweep ? visibility::VisibilityAlgorithm::Sweep : visibility::VisibilityAlgorithm::March;
    s.visibility.rays =
        raysGiven
            ? rays
            : p.integer("rays",
                        sweep ? (c > 9 ? visibility::kSweepRaysFine : visibility::kSweepRaysCoarse)
                              : std::max(32, minRays),
                        minRays, 4096);
    if (sweep && s.visibility.rays != visibility::kSweepRaysCoarse &&
        s.visibility.rays != visibility::kSweepRaysFine)
        p.fail("rays",
               "must be 26 or 98 with algorithm sweep, got " + std::to_string(s.visibility.rays),
               "the sweep's rays are the lattice steps: 26 (|v| ≤ 1 per axis) or 98 (≤ 2)");
    s.visibility.radiusVoxels = p.number("radius", 16.0, 0.5, 256.0);
    s.visibility.threads = scene.render.threads;
    if (p.has("lod_budget_mb") && p.has("data_reduction"))
        p.fail("lod_budget_mb", "and data_reduction both set the LOD budget", "give one of them");
    if (p.has("lod_budget_mb"))
        s.budgetMb = p.number("lod_budget_mb", 0.0, 1e-3, 1e6);
    else
        s.dataReduction = p.number("data_reduction", s.dataReduction, 1.0, 1e6);
    if (kind == Kind::ShGlobal) {
        // One point has nothing to interpolate between (a 1³ grid shaded everything alike).
        s.global.resolution = p.integer("global_resolution", 64, 2, 1024);
        s.global.nearFromLocal = p.choice("global_near", "local", {"local", "grid"}) == "local";
        s.global.integration =
            p.choice("global_integration", "recursive", {"recursive", "piecewise"}) == "recursive"
                ? visibility::GlobalIntegration::Recursive
                : visibility::GlobalIntegration::Piecewise;
        s.global.threads = scene.render.threads;
    }
    return s;
}

/// The SH methods' ringing window (render/sh_shading.h): `window` none|hanning|lanczos|gaussian,
/// `window_strength` (Gaussian λ only). Band factors for `coefficients`, empty for none.
std::vector<double> parseShWindowParams(ParamReader& p, int coefficients) {
    const std::string name = p.choice("window", "none", {"none", "hanning", "lanczos", "gaussian"});
    double strength = 0.0;
    if (name == "gaussian")
        strength = p.number("window_strength", 0.02, 0.0, 10.0);
    else if (p.has("window_strength"))
        p.fail("window_strength", "applies to window 'gaussian' only",
               "remove it, or set window to \"gaussian\"");
    if (name == "none") return {};
    return sh::windowFactors(sh::parseShWindow(name), sh::shBandForCount(coefficients), strength);
}

/// ritschel's own parameters (see the header comment).
visibility::HierarchicalVisibilityOptions parseRitschelParams(const io::Scene& scene,
                                                              ParamReader& p) {
    visibility::HierarchicalVisibilityOptions o;
    o.coefficients = p.integer("coefficients", 4, 1, 16);
    const int c = o.coefficients;
    if (c != 1 && c != 4 && c != 9 && c != 16)
        p.fail("coefficients", "must be 1, 4, 9 or 16, got " + std::to_string(c),
               "1 is ambient occlusion; 4, 9, 16 are SH bands 1, 2, 3");
    o.rays = p.integer("rays", std::max(32, visibility::kMinRaysPerCoefficient * c),
                       visibility::kMinRaysPerCoefficient * c, 4096);
    o.patterns = p.integer("patterns", o.patterns, 1, visibility::kMaxPatterns);
    o.subsample = p.integer("subsample", o.subsample, 1, visibility::kMaxSubsample);
    o.quantize8 = p.boolean("quantize_8bit", false);
    o.hierarchical = p.boolean("hierarchical", true);
    // Absent: to the volume's boundary (hierarchical_visibility.h says why).
    if (p.has("max_distance")) o.maxDistanceVoxels = p.number("max_distance", 0.0, 0.5, 1e6);
    o.seed = scene.render.seed;
    o.threads = scene.render.threads;
    return o;
}

/// Options of the caster from the scene and the method params (read strictly).
render::RenderOptions parseOptions(Kind kind, const io::Scene& scene, ParamReader& p) {
    render::RenderOptions o;
    o.mode = modeOf(kind);
    if (kind != Kind::PathTrace) {  // the marcher's own knobs
        o.stepVoxels = float(p.number("step", scene.render.stepVoxels, 0.01, 16.0));
        o.preintegrated = p.boolean("preintegrated", true);
        o.emptySpaceSkipping = p.boolean("empty_space_skipping", true);
        o.earlyTermination = p.boolean("early_termination", true);
        o.jitter = p.boolean("jitter", true);
    }
    if (kind == Kind::EmissionAbsorption) o.ambient = float(p.number("ambient", 1.0, 0.0, 1e6));
    if (kind == Kind::Gradient || kind == Kind::Iso) {
        o.blinnPhong.ambient = float(p.number("ambient", o.blinnPhong.ambient, 0.0, 1e6));
        o.blinnPhong.diffuse = float(p.number("diffuse", o.blinnPhong.diffuse, 0.0, 1e6));
    }
    if (kind == Kind::Gradient) {
        const bool specular = wantsEffect(scene, "specular");
        if (!specular && p.has("specular"))
            p.fail("specular", "is set but the scene's effects list omits 'specular'",
                   "add \"specular\" to effects or remove the parameter");
        o.blinnPhong.specular =
            specular ? float(p.number("specular", o.blinnPhong.specular, 0.0, 1e6)) : 0.f;
        if (!specular) p.used["specular"] = 0.0;
        o.blinnPhong.shininess = float(p.number("shininess", o.blinnPhong.shininess, 1.0, 1e4));
        o.centralDifferences = p.boolean("central_differences", o.centralDifferences);
    }
    // The SH methods' ambient sky (render/sh_shading.h; registered since it was added, read only
    // from 5 December: before, `ambient` was accepted and silently ignored).
    if (isSh(kind)) o.shAmbient = float(p.number("ambient", 0.0, 0.0, 1e6));
    if (kind == Kind::ShLocal || kind == Kind::ShGlobal) {
        o.shNearShadow = p.boolean("near_shadow", true);
        // Voxels traced at every level (render/sh_shading.h kNearShadowSpacings' note): accuracy
        // against the path tracer for frame time.
        // Like near_shadow, it changes nothing with sh-global's global_near "grid" (no near
        // factor to trace from).
        o.shNearTraceVoxels = float(p.number("near_trace", 0.0, 0.0, 64.0));
        if (!o.shNearShadow && o.shNearTraceVoxels > 0.f)
            p.fail("near_trace", "is set but near_shadow is false",
                   "set near_shadow to true or remove near_trace");
    }
    if (kind == Kind::Iso || kind == Kind::IsoLattice) {
        if (p.has("iso_value")) o.isoValue = float(p.number("iso_value", 0.0, -1e9, 1e9));
        o.blinnPhong.specular = 0.f;  // Lambertian (ARCHITECTURE §1)
    }

    o.seed = scene.render.seed;
    o.threads = scene.render.threads;
    o.terminationTransmittance = float(scene.render.termination);
    o.background = glm::vec3(scene.image.background);
    for (const auto& c : scene.clipPlanes)
        o.clipPlanes.push_back({c.point, c.normal, c.shadowsFromRemoved});
    if (scene.cropBox)
        o.cropBox = render::CropBox{scene.cropBox->min, scene.cropBox->max,
                                    scene.cropBox->shadowsFromRemoved};
    return o;
}

/// iso-lattice's own parameters (pipeline/iso_shading.h, iso/lattice.h).
struct IsoLatticeParams {
    IsoShadingOptions shading;
    iso::LatticeOptions lattice;
    double vicinityRadiusVoxels = 8.0;
};

/// Vicinity shading's default radius, voxels (smallest spacing): Stewart's vicinity is the
/// neighbourhood whose occluders matter for shape perception; 8 voxels shows a bone's grooves
/// and the gaps between vertebrae without the darkening of a whole-body occlusion.
constexpr double kDefaultVicinityVoxels = 8.0;

IsoLatticeParams parseIsoLatticeParams(const io::Scene& scene, ParamReader& p) {
    IsoLatticeParams q;
    q.shading.shading = isoShadingFromName(p.choice("shading", "lattice", isoShadingNames()));
    const bool usesSamples = q.shading.shading == IsoShading::Lattice ||
                             q.shading.shading == IsoShading::Paths ||
                             q.shading.shading == IsoShading::Vicinity;
    auto only = [&](const std::string& key, bool used, const std::string& which) {
        if (!used && p.has(key))
            p.fail(key,
                   "is not read by shading '" + isoShadingNames()[int(q.shading.shading)] + "'",
                   "it applies to shading " + which + "; remove it");
    };
    only("samples", usesSamples, "lattice, paths and vicinity");
    const bool gi =
        q.shading.shading == IsoShading::Lattice || q.shading.shading == IsoShading::Paths;
    only("bounces", gi, "lattice and paths");
    const bool lat = q.shading.shading == IsoShading::Lattice;
    for (const char* k :
         {"lattice_resolution", "lattice_mode", "sh_order", "lattice_memory_mb", "lattice_texels"})
        only(k, lat, "lattice");
    only("vicinity_radius", q.shading.shading == IsoShading::Vicinity, "vicinity");
    const bool ph = q.shading.shading == IsoShading::Phong;
    for (const char* k : {"ambient", "diffuse", "specular", "shininess"}) only(k, ph, "phong");
    if (usesSamples) q.shading.samples = p.integer("samples", 100, 1, 1 << 20);
    q.lattice.samples = q.shading.samples;
    if (gi) q.lattice.bounces = p.integer("bounces", 1, 0, 16);
    if (lat) {
        q.lattice.resolution = p.number("lattice_resolution", 1.0, iso::kMinLatticeResolution, 8.0);
        q.lattice.mode = p.choice("lattice_mode", "irradiance", {"irradiance", "sh"}) == "sh"
                             ? iso::LatticeMode::ShTransfer
                             : iso::LatticeMode::Irradiance;
        if (q.lattice.mode == iso::LatticeMode::ShTransfer)
            q.lattice.shOrder = p.integer("sh_order", 5, 1, 5);
        else
            only("sh_order", false, "lattice with lattice_mode 'sh'");
        q.lattice.memoryBudgetMiB = p.number("lattice_memory_mb", 4096.0, 1.0, 1 << 20);
        q.lattice.placement = p.choice("lattice_texels", "surface", {"surface", "own"}) == "own"
                                  ? iso::TexelPlacement::OwnIsosurface
                                  : iso::TexelPlacement::OnSurface;
    }
    if (q.shading.shading == IsoShading::Vicinity)
        q.vicinityRadiusVoxels = p.number("vicinity_radius", kDefaultVicinityVoxels, 0.5, 1e4);
    if (ph) {
        render::BlinnPhongParams& b = q.shading.phong;
        b.ambient = float(p.number("ambient", b.ambient, 0.0, 1e6));
        b.diffuse = float(p.number("diffuse", b.diffuse, 0.0, 1e6));
        b.specular = float(p.number("specular", b.specular, 0.0, 1e6));
        b.shininess = float(p.number("shininess", b.shininess, 1.0, 1e4));
    }
    q.lattice.seed = scene.render.seed;
    q.lattice.threads = scene.render.threads;
    return q;
}

/// The lattice of method iso-lattice: kept in the memory cache, its texels filled lazily by the
/// frames (the one mutable artifact: frames of one process add texels, never change them).
struct LatticeArtifact {
    std::shared_ptr<iso::IlluminationLattice> lattice;
    mutable std::uint64_t lightsKey =
        0;  ///< SH transfer: the lights its irradiance slots are dotted with
};

/// Reference mode's defaults: traced until the image's estimated relative error (NRMS against the
/// converged image) is 1 % — at mid-grey about one 8-bit display step, under the 2/255 the
/// accuracy tables count — or this many spp. A study that needs less noise sets target_error.
constexpr double kReferenceTargetError = 0.01;
constexpr int kReferenceMaxSpp = 1 << 14;
/// A reference traces its own stream of random numbers, not the scene seed's: a path-traced
/// variant with the same seed shares its first samples, and measured against it showed half its
/// true error (a sweep's 256-spp variant at 0.025 NRMSE against a 368-spp reference, 0.046 with
/// another seed) and errors that rose with more samples.
constexpr std::uint64_t kReferenceStream = 0x7265666572656e63ull;  // "referenc"

/// The denoiser's settings from method.params `denoise` / `denoise_target`; nullopt = off.
/// Reference mode never denoises: `denoise: true` there is an error, and an absent key stays out
/// of the params as used (so the reference's cache key is what it was before the denoiser).
std::optional<pathtrace::DenoiseOptions> parseDenoiseParams(const io::Scene& scene,
                                                            const render::RenderOptions& o,
                                                            ParamReader& p, bool reference) {
    std::string mode = "auto";
    if (p.has("denoise")) {
        const json& v = scene.method.params["denoise"];
        if (v.is_boolean())
            mode = v.get<bool>() ? "true" : "false";
        else if (!(v.is_string() && v.get<std::string>() == "auto"))
            p.fail("denoise", "must be true, false or \"auto\", got " + v.dump(),
                   "\"auto\" denoises unless reference is true");
        p.used["denoise"] = v;
    }
    if (reference) {
        if (mode == "true")
            p.fail("denoise", "is true but reference renders are never denoised",
                   "remove denoise or set it to false (or set reference to false)");
        if (p.has("denoise_target"))
            p.fail("denoise_target", "applies only when denoising, and reference renders never are",
                   "remove denoise_target");
        return std::nullopt;
    }
    if (!p.has("denoise")) p.used["denoise"] = "auto";
    if (mode == "false") {
        if (p.has("denoise_target"))
            p.fail("denoise_target", "is set but denoise is false",
                   "remove denoise_target or set denoise to true or \"auto\"");
        return std::nullopt;
    }
    pathtrace::DenoiseOptions d;
    d.targetError = p.number("denoise_target", d.targetError, 1e-4, 1.0);
    d.threads = o.threads;
    return d;
}

/// `max_bounces` of the multiple-scattering methods (pathtrace, pvrt): the "multiple_scattering"
/// effect decides the default (kDefaultMaxBounces, else 1), and more than one bounce without it
/// is refused.
int parseMaxBounces(const io::Scene& scene, ParamReader& p) {
    const bool multiple = wantsEffect(scene, "multiple_scattering");
    if (!multiple && p.has("max_bounces") && p.integer("max_bounces", 1, 1, 1000) > 1)
        p.fail("max_bounces",
               "asks for more than one bounce but the scene's effects omit "
               "'multiple_scattering'",
               "add \"multiple_scattering\" to effects or set max_bounces to 1");
    return p.integer("max_bounces", multiple ? kDefaultMaxBounces : 1, 1, 1000);
}

/// The path tracer's options from the scene and method.params. Multiple scattering is the
/// "multiple_scattering" effect: without it paths stop after one scattering event.
pathtrace::Options parsePathTraceOptions(const io::Scene& scene, const render::RenderOptions& o,
                                         ParamReader& p, bool& reference) {
    pathtrace::Options t;
    reference = p.boolean("reference", false);
    t.samplesPerPixel = p.integer("spp", reference ? kReferenceMaxSpp : 64, 1, 1 << 20);
    t.maxSeconds = p.number("seconds", 0.0, 0.0, 1e6);
    t.targetError = p.number("target_error", reference ? kReferenceTargetError : 0.0, 0.0, 1.0);
    t.maxBounces = parseMaxBounces(scene, p);
    t.phaseG = float(p.number("phase_g", 0.0, -0.99, 0.99));
    const std::string scattering = p.choice("scattering", "phase", {"phase", "brdf", "hybrid"});
    t.scattering = scattering == "brdf"     ? pathtrace::Scattering::Brdf
                   : scattering == "hybrid" ? pathtrace::Scattering::Hybrid
                                            : pathtrace::Scattering::Phase;
    if (scattering != "hybrid" && p.has("gradient_factor"))
        p.fail("gradient_factor",
               "applies only to hybrid scattering but scattering is \"" + scattering + "\"",
               "remove gradient_factor or set scattering to \"hybrid\"");
    if (scattering == "hybrid")
        t.gradientFactor = float(p.number("gradient_factor", 0.5, 0.0, 1.0));
    t.majorantGrid = p.boolean("majorant_grid", true);
    t.pixelJitter = p.boolean("antialias", !reference);
    // Adaptive sampling spends the same samples where the noise is (consistent, not unbiased):
    // the progressive picture's default, never a reference's.
    t.adaptive = p.boolean("adaptive", !reference);
    if (reference && t.adaptive)
        p.fail("adaptive", "is true but a reference render samples every pixel alike (unbiased)",
               "remove adaptive or set it to false (or set reference to false)");
    t.seed = reference ? core::hashCounters(o.seed, kReferenceStream) : o.seed;
    t.threads = o.threads;
    t.background = o.background;
    t.clipPlanes = o.clipPlanes;
    t.cropBox = o.cropBox;
    t.apertureMm = scene.camera.apertureMm;
    t.focusMm = scene.camera.focusMm.value_or(0.0);
    return t;
}

/// Errors of the render library name its own option; the scene calls them by these keys.
[[noreturn]] void rethrowAsScene(const io::Scene& scene, const InputError& e) {
    static const std::map<std::string, std::string> kSceneKey = {
        {"step", "render.step"},
        {"termination", "render.termination"},
        {"iso_value", "method.params.iso_value"},
        {"image size", "image.width"},
        {"rays", "method.params.rays"}};
    if (e.source() == "render options" || e.source() == "camera" ||
        e.source() == "local visibility") {
        const auto it = kSceneKey.find(e.field());
        throw InputError(scene.source, it != kSceneKey.end() ? it->second : e.field(), e.problem(),
                         e.fix());
    }
    throw e;
}

/// Grey level (of 1) a MIP's background may reach (MinIP: fall short of white) with the TF's own
/// window: about five 8-bit levels.
constexpr float kBackgroundGrey = 0.02f;

/// The grey window of a MIP (MinIP) whose scene sets none: the TF's own window when the data's
/// low (high) end — a MIP's (MinIP's) background — maps to black (white) and the other end reaches
/// past mid-grey, else the data's robust range. (A CT preset on a head angio stored 0..4095 put
/// its background at 21 % grey: a grey box.) A flat volume's one value at mid-grey: the TF's window
/// lies past it (the generic TF shows [v + ½, v + 1]), and a black box is no picture of it.
optics::Window extremumWindow(Kind kind, const optics::Window& w, const core::Volume& volume) {
    const auto range = volume.physicalRange();
    // (Wide enough that the window's ends survive float rounding far from 0: at 1e8 a float
    // steps by 8.)
    if (!(range[0] < range[1]))
        return {float(range[0]), float(std::max(1.0, 1e-4 * std::abs(range[0])))};
    const auto [lo, hi] = optics::robustRange(volume);
    // Where the data's robust ends land on the window's grey ramp (0 black, 1 white).
    const float atLo = (lo - w.lo()) / w.width, atHi = (hi - w.lo()) / w.width;
    const bool fits = kind == Kind::Mip
                          ? atLo <= kBackgroundGrey && atHi >= 0.5f  // black air, bright top
                          : atHi >= 1.f - kBackgroundGrey && atLo <= 0.5f;
    if (fits) return w;
    return {0.5f * (lo + hi), hi > lo ? hi - lo : 1.f};
}

/// A CT preset (in HU) on a volume with no air: its values are not Hounsfield units (8-bit
/// windowed exports, raw CT numbers), and the preset shows the wrong tissue or nothing.
/// Returns whether it warned.
bool warnIfNotHounsfield(Run& run, const optics::TransferFunction& tf, const grid::BrickGrid& grid,
                         std::vector<std::string>* sink = nullptr) {
    const io::TransferFunctionDesc& d = run.scene().transferFunction;
    if (d.preset.rfind("ct-", 0) != 0 || d.window) return false;
    if (grid.valueLo() < kNoAirAbove) return false;
    std::ostringstream os;
    os << "'" << tf.name() << "' expects Hounsfield units (air at -1000); this volume holds "
       << grid.valueLo() << ".." << grid.valueHi()
       << " (not HU: use \"generic\", or set transfer_function.window to where the tissue lies)";
    if (sink)
        sink->push_back(os.str());
    else
        run.warn(os.str());
    return true;
}

/// Coverage (alpha) below which a pixel shows nothing: under one 8-bit display level.
constexpr float kVisibleAlpha = 0.5f / 255.f;
/// A thin lens whose rays spread more than this off each pixel's line (half-aperture over focus
/// distance) is named as the cause of an empty path-traced image: a real depth of field stays
/// within a few degrees (a 10 mm aperture focused at 300 mm: 0.95°).
constexpr double kMaxUnblamedLensSpreadDeg = 30.0;

/// Why an image shows nothing, and what to do: the TF (or isovalue) leaves every skip cell empty
/// (`anyCellVisible` false), what rays met is too faint (`maxAlpha`, the film's largest coverage,
/// above 0), or no camera ray meets what it shows.
std::string emptyImageReason(const Run& run, Kind kind, bool anyCellVisible, float maxAlpha,
                             const optics::TransferFunction& tf, const grid::BrickGrid& grid,
                             float isoValue = NAN) {
    const std::string& method = run.scene().method.name;
    const bool iso = kind == Kind::Iso || kind == Kind::IsoLattice;
    // What the TF (or isovalue) shows exists in the data, yet no cell holds it: the clip planes
    // and crop box removed it (iso-lattice blamed the TF).
    const bool shownInData = iso ? isoValue >= grid.valueLo() && isoValue <= grid.valueHi()
                                 : !tf.transparentOver(grid.valueLo(), grid.valueHi());
    if (!anyCellVisible && shownInData && (!run.scene().clipPlanes.empty() || run.scene().cropBox))
        return "the image is empty: clip_planes and crop_box remove everything '" + method +
               "' shows (move them so that part of it is kept)";
    if (!anyCellVisible) {
        // The TF (or isovalue) leaves every cell empty: compare what it shows with what is there.
        float lo = INFINITY, hi = -INFINITY;
        for (const auto& p : tf.points())
            if (p.extinction > 0.f) lo = std::min(lo, p.value), hi = std::max(hi, p.value);
        std::ostringstream os;
        os << "the image is empty: ";
        if (iso) {
            os << "the isovalue lies outside this volume's values [" << grid.valueLo() << ", "
               << grid.valueHi() << "] (set method.params.iso_value inside them)";
        } else {
            os << "transfer function '" << tf.name() << "' is transparent over all of this "
               << "volume's values [" << grid.valueLo() << ", " << grid.valueHi() << "]";
            if (lo <= hi)
                os << "; it shows [" << lo << ", " << hi << "]";
            else
                os << "; it shows nothing anywhere";
            os << " (choose a preset for this modality, or set transfer_function.window)";
        }
        return os.str();
    }
    if (maxAlpha > 0.f) {
        // Rays met matter, too thin or faint for its extinction (per mm) to reach one display
        // level anywhere: a volume 0.0055 mm across (spacing 1e-4 mm) under 'generic' — said as
        // the camera looking past it until 7 December.
        const core::Geometry& g = run.get<LoadedVolume>("load_volume")->volume.geometry();
        std::ostringstream os;
        os << "the image is empty: what '" << method << "' shows is too faint, at most "
           << 100.0 * maxAlpha << " % opaque on any pixel (the volume is "
           << glm::length(glm::dvec3(g.dims) * g.spacing) << " mm across and '" << tf.name()
           << "' absorbs at most " << tf.maxExtinction() << " per mm: check the voxel spacing, "
           << g.spacing.x << " x " << g.spacing.y << " x " << g.spacing.z
           << " mm, or raise the TF's opacity)";
        return os.str();
    }
    const io::CameraDesc& cam = run.scene().camera;
    if (kind == Kind::PathTrace && cam.apertureMm > 0.0 && cam.focusMm) {
        // A lens focused a hair from the eye spreads each pixel's rays sideways past everything
        // (aperture 20 mm at focus_distance 0.001 mm: 89.99°) — blamed on the aim until 7 December.
        const double spread = glm::degrees(std::atan(0.5 * cam.apertureMm / *cam.focusMm));
        if (spread > kMaxUnblamedLensSpreadDeg) {
            std::ostringstream os;
            os << "the image is empty: camera.aperture " << cam.apertureMm
               << " mm focused at focus_distance " << *cam.focusMm
               << " mm spreads each pixel's rays up to " << spread << "° off its line, past what '"
               << method
               << "' shows (set focus_distance to the distance of the anatomy, or \"auto\", or "
                  "a smaller aperture)";
            return os.str();
        }
    }
    return "the image is empty: no camera ray meets what '" + method +
           "' shows here (the camera looks past it, or clip_planes/crop_box remove it; "
           "check camera.target, camera.eye/azimuth/elevation, clip_planes and crop_box)";
}

float maxAlpha(const core::ImageRGBA& film) {
    float m = 0.f;
    for (std::size_t i = 3; i < film.pixels.size(); i += 4) m = std::max(m, film.pixels[i]);
    return m;
}

bool filmShowsAnything(const core::ImageRGBA& film) { return maxAlpha(film) > kVisibleAlpha; }

/// Never a black image without a word: says why nothing shows and what to do.
void warnIfNothingShows(Run& run, Kind kind, const core::ImageRGBA& film,
                        const render::RenderStats& stats, const optics::TransferFunction& tf,
                        const grid::BrickGrid& grid, float isoValue) {
    if (filmShowsAnything(film)) return;
    // A MIP/MinIP whose rays ran shows the background's grey on purpose.
    if (stats.skipCellsVisible != 0 && stats.rays != 0 &&
        (kind == Kind::Mip || kind == Kind::MinIp))
        return;
    run.warn(emptyImageReason(run, kind, stats.skipCellsVisible != 0, maxAlpha(film), tf, grid,
                              isoValue));
}

std::string dims(const glm::ivec3& d) {
    return std::to_string(d.x) + "x" + std::to_string(d.y) + "x" + std::to_string(d.z);
}

/// A path-traced image with what it says about itself: kept together so that a cached reference
/// reports its spp, error and warnings like a fresh one.
struct TracedImage {
    core::ImageRGBA image, stdError;
    core::ImageRGBA denoised;  ///< the display image when denoised (never cached: not in reference)
    json details;
    std::vector<std::string> warnings;
    std::size_t bytes() const {
        return (image.pixels.size() + stdError.pixels.size() + denoised.pixels.size()) * 4;
    }
};

/// Largest cached image side (guards the read allocation against a damaged header).
constexpr std::uint64_t kMaxCachedImagePixels = std::uint64_t(1) << 28;

const Codec& tracedImageCodec() {
    // 2: shadow rays by residual ratio tracking — the same expectation, other samples for a seed,
    // so a disk cache from before does not hand back an image a fresh render would not give.
    // 3: the target-error stop reads the RGB error (more samples on coloured scenes), and the
    // details carry expected_nrmse and the empty-image warnings.
    // 4: references trace their own random stream (kReferenceStream), not the scene seed's.
    // 5: a phase event that ends a path also samples the phase function toward area and
    // environment lights (MIS): other samples under such lights; and a 1-spp error is null.
    static const Codec c{
        5,
        [](const Artifact& a, ByteWriter& w) {
            const auto& t = *a.as<TracedImage>();
            w.pod(std::int32_t(t.image.width));
            w.pod(std::int32_t(t.image.height));
            w.array(t.image.pixels);
            w.array(t.stdError.pixels);
            w.string(t.details.dump());
            w.pod(std::uint64_t(t.warnings.size()));
            for (const auto& s : t.warnings) w.string(s);
        },
        [](ByteReader& r) {
            auto t = std::make_shared<TracedImage>();
            const int wd = r.pod<std::int32_t>(), ht = r.pod<std::int32_t>();
            if (wd < 1 || ht < 1 || std::uint64_t(wd) * std::uint64_t(ht) > kMaxCachedImagePixels)
                badPayload("image size does not fit");
            const std::uint64_t floats = std::uint64_t(wd) * std::uint64_t(ht) * 4;
            t->image = core::ImageRGBA(wd, ht);
            t->stdError = core::ImageRGBA(wd, ht);
            t->image.pixels = r.array<float>(floats);
            t->stdError.pixels = r.array<float>(floats);
            if (t->image.pixels.size() != floats || t->stdError.pixels.size() != floats)
                badPayload("image pixels do not fit its size");
            t->details = json::parse(r.string(), nullptr, false);
            if (t->details.is_discarded()) badPayload("details are not JSON");
            const auto n = r.pod<std::uint64_t>();
            if (n > r.remaining()) badPayload("warning count does not fit");
            for (std::uint64_t i = 0; i < n; ++i) t->warnings.push_back(r.string());
            const std::size_t bytes = t->bytes();
            return Artifact::of<TracedImage>(std::move(t), bytes);
        }};
    return c;
}

/// Runs the path tracer over the same volume, TF table, majorant cells, lights and camera as the
/// ray caster's stages.
std::shared_ptr<const TracedImage> tracePath(
    Run& run, pathtrace::Options pt,
    std::optional<pathtrace::DenoiseOptions> denoise = std::nullopt) {
    const auto loaded = run.get<LoadedVolume>("load_volume");
    const auto tfa = run.get<TfArtifact>("transfer_function");
    if (run.has("lights")) pt.lights = *run.get<LightList>("lights");
    const auto camera = run.get<render::Camera>("camera");
    pathtrace::Stats st;
    auto out = std::make_shared<TracedImage>();
    try {
        const pathtrace::PathTracer tracer(
            std::shared_ptr<const core::Volume>(loaded, &loaded->volume), tfa->table,
            run.get<grid::BrickMajorants>("skip_cells"), pt);
        out->image = tracer.render(*camera, run.progress(), &st, &out->stdError);
        if (denoise) {
            // The guides' depth tolerance: one voxel of the smallest spacing.
            const glm::dvec3 sp = loaded->volume.geometry().spacing;
            denoise->depthFloorMm = float(std::min({sp.x, sp.y, sp.z}));
            core::Stopwatch guideClock;
            const pathtrace::Guides guides = tracer.guides(*camera);
            const double guideSeconds = guideClock.seconds();
            pathtrace::DenoiseStats ds;
            // One sample per pixel has no variance of its own (reported 0: the filter left the
            // noisiest image untouched): the neighbourhood's spread stands in for it.
            const bool oneSample = st.samplesPerPixel == 1;
            out->denoised = pathtrace::denoise(
                out->image,
                oneSample ? pathtrace::neighbourhoodStdError(out->image) : out->stdError, guides,
                *denoise, &ds);
            out->details["denoise"] = {
                {"applied", true},
                {"variance", oneSample ? "3x3 neighbourhood (1 spp)" : "per pixel"},
                {"target_error", denoise->targetError},
                {"mean_strength", ds.meanStrength},
                {"filtered_fraction", ds.filteredFraction},
                {"full_strength_fraction", ds.fullFraction},
                {"iterations", denoise->iterations},
                {"guide_seconds", guideSeconds},
                {"filter_seconds", ds.seconds}};
        } else {
            out->details["denoise"] = {{"applied", false},
                                       {"reason", "method.params.denoise is false"}};
        }
    } catch (const InputError& e) {
        if (e.source() == "pathtrace")
            throw InputError(run.scene().source, "method.params." + e.field(), e.problem(),
                             e.fix());
        throw;
    }
    json& d = out->details;
    d["pathtrace"] = {{"spp", st.samplesPerPixel},
                      {"seconds", st.seconds},
                      {"paths_per_second", st.seconds > 0 ? double(st.paths) / st.seconds : 0.0},
                      {"relative_std_error", st.relativeStdError},
                      {"expected_nrmse", st.expectedNrmse},
                      {"target_error", pt.targetError},
                      {"target_reached", st.targetReached},
                      {"real_collisions", st.realCollisions},
                      {"null_collisions", st.nullCollisions},
                      {"shadow_rays", st.shadowRays},
                      {"majorant_violations", st.majorantViolations},
                      {"null_collision_budget_exceeded", st.budgetExceeded},
                      {"max_bounces", pt.maxBounces},
                      {"majorant_grid", pt.majorantGrid},
                      {"adaptive", st.adaptive},
                      {"pixel_spp_min", st.minPixelSamples},
                      {"pixel_spp_max", st.maxPixelSamples},
                      {"surface_events", st.surfaceEvents},
                      {"acceleration_bytes", st.accelerationBytes}};
    if (st.budgetExceeded > 0)
        out->warnings.push_back(
            std::to_string(st.budgetExceeded) +
            " flights met a cell so dense (sigma_t x length > 4096) that they were taken as "
            "blocked there: lower transfer_function.extinction_scale if this is not meant");
    if (st.majorantViolations > 0)
        out->warnings.push_back(
            std::to_string(st.majorantViolations) +
            " samples exceeded their cell's majorant: the image may be biased (please report)");
    if (pt.targetError > 0.0 && !st.targetReached && std::isfinite(st.relativeStdError)) {
        // %g: a target of 1e-9 printed as "0.000000 %" (probe).
        std::ostringstream os;
        os << "the path tracer stopped at " << st.samplesPerPixel
           << " spp with an estimated error of " << 100.0 * st.relativeStdError
           << " % above method.params.target_error (" << 100.0 * pt.targetError
           << " %): raise method.params.spp or method.params.seconds";
        out->warnings.push_back(os.str());
    }
    if (run.has("brick_grid")) {
        // As the ray caster's methods say it (the warnings travel with a cached reference).
        const grid::BrickGrid& bricks = *run.get<grid::BrickGrid>("brick_grid");
        if (!warnIfNotHounsfield(run, tfa->tf, bricks, &out->warnings) &&
            !filmShowsAnything(out->image))
            out->warnings.push_back(
                emptyImageReason(run, Kind::PathTrace,
                                 run.get<grid::BrickMajorants>("skip_cells")->nonEmptyCount() > 0,
                                 maxAlpha(out->image), tfa->tf, bricks));
    }
    const render::Camera& cam = *camera;
    d["camera"] = {{"eye", {cam.eye().x, cam.eye().y, cam.eye().z}},
                   {"forward", {cam.forward().x, cam.forward().y, cam.forward().z}},
                   {"up", {cam.up().x, cam.up().y, cam.up().z}}};
    if (pt.apertureMm > 0.0) {
        d["camera"]["aperture_mm"] = pt.apertureMm;
        d["camera"]["focus_distance_mm"] = st.focusMm;
        d["camera"]["autofocus"] = st.autofocused;
    }
    return out;
}

/// The pathtrace method's image stage: a traced image (fresh, or the cached reference) with its
/// details, warnings and standard-error image handed to the run.
Artifact publishTraced(Run& run, const TracedImage& t) {
    for (auto it = t.details.begin(); it != t.details.end(); ++it) run.details()[it.key()] = *it;
    for (const auto& w : t.warnings) run.warn(w);
    run.addImage("std_error", std::make_shared<const core::ImageRGBA>(t.stdError));
    if (!t.denoised.pixels.empty())
        run.addImage("denoised", std::make_shared<const core::ImageRGBA>(t.denoised));
    auto film = std::make_shared<const core::ImageRGBA>(t.image);
    const std::size_t bytes = film->pixels.size() * sizeof(float);
    return Artifact::of<core::ImageRGBA>(std::move(film), bytes);
}

// ---- SH visibility stages ----------------------------------------------------------------------

/// What removes matter for the light too (shadows_from_removed false): the kept half-spaces of
/// those clip planes and of the crop box, and the scene's description of them (the cache key);
/// and the description of the section-view ones (true), which remove matter for the camera only
/// (`sectionKey`: for what depends on them, PVRT's photons).
struct LightCuts {
    std::vector<core::HalfSpace> kept;
    json key = json::array();
    json sectionKey = json::array();
    bool any() const { return !kept.empty(); }
};

LightCuts lightCuts(const render::RenderOptions& o) {
    LightCuts c;
    for (const render::ClipPlane& p : o.clipPlanes) {
        if (!p.shadowsFromRemoved) c.kept.push_back({p.point, p.normal});
        (p.shadowsFromRemoved ? c.sectionKey : c.key)
            .push_back({{"point", {p.point.x, p.point.y, p.point.z}},
                        {"normal", {p.normal.x, p.normal.y, p.normal.z}}});
    }
    if (o.cropBox) {
        if (!o.cropBox->shadowsFromRemoved)
            for (const core::HalfSpace& f : core::boxHalfSpaces(o.cropBox->min, o.cropBox->max))
                c.kept.push_back(f);
        const glm::dvec3 &lo = o.cropBox->min, &hi = o.cropBox->max;
        (o.cropBox->shadowsFromRemoved ? c.sectionKey : c.key)
            .push_back({{"crop_min", {lo.x, lo.y, lo.z}}, {"crop_max", {hi.x, hi.y, hi.z}}});
    }
    return c;
}

/// The local visibility field the light sees: clip-aware when something removes matter for it.
std::shared_ptr<const visibility::LocalVisibility> lightLocalVisibility(const Run& run,
                                                                        bool clipped) {
    return run.get<visibility::LocalVisibility>(clipped ? "clip_local_visibility"
                                                        : "local_visibility");
}

/// block_pyramid ← volume (once per volume); multires_grid ← pyramid + TF + LOD budget;
/// local_visibility ← grid + TF + rays/coefficients/radius. A light or camera change reruns none.
Stage blockPyramidStage(bool forSweep) {
    Stage pyramid{"block_pyramid", StageKind::Precompute, {"load_volume"}};
    // The line sweep's float copy of the voxels is kept with the pyramid (TF-independent): made
    // here, so the artifact's size counts it and no TF update pays for it. A pyramid with it is
    // another artifact than one without (its own key): sizes, and so the memory the accuracy
    // study charges a variant, never depend on which method ran first.
    pyramid.key = [forSweep](const Run& run) {
        KeyBuilder k(run, "block_pyramid");
        k.stage("load_volume");
        if (forSweep) k.text("float voxels");
        return k.value();
    };
    pyramid.compute = [forSweep](Run& run) {
        auto p = std::make_shared<const visibility::BlockPyramid>(visibility::BlockPyramid::build(
            run.get<LoadedVolume>("load_volume")->volume, run.progress()));
        if (forSweep) p->flatVoxels();
        const std::size_t bytes = p->bytes();
        return Artifact::of<visibility::BlockPyramid>(std::move(p), bytes);
    };
    pyramid.notOnDisk = "rebuilt from the volume in one pass, faster than reading it back";
    pyramid.describe = [](const Run&, const Artifact& a) {
        const auto& p = *a.as<visibility::BlockPyramid>();
        return std::to_string(p.blockCount()) + " blocks of 16^3 at 5 levels, " +
               std::to_string(p.bytes() >> 20) + " MB" +
               (p.flatBytes() > 0 ? " (" + std::to_string(p.flatBytes() >> 20) +
                                        " MB of it the voxels copied for the line sweep)"
                                  : std::string());
    };
    return pyramid;
}

void addVisibilityStages(Plan& plan, const ShParams& params, bool global, const LightCuts& cuts) {
    plan.stages.push_back(
        blockPyramidStage(params.visibility.algorithm == visibility::VisibilityAlgorithm::Sweep));

    const json budgetKey = params.budgetKey();
    Stage grid{
        "multires_grid", StageKind::Precompute, {"block_pyramid", "transfer_function", "method"}};
    grid.key = [budgetKey](const Run& run) {
        return KeyBuilder(run, "multires_grid")
            .stage("block_pyramid")
            .stage("transfer_function")
            .json(budgetKey)
            .value();
    };
    grid.compute = [params](Run& run) {
        const auto pyr = run.get<visibility::BlockPyramid>("block_pyramid");
        const auto tfa = run.get<TfArtifact>("transfer_function");
        visibility::LodBudget budget;
        try {
            budget = params.budget(pyr->geometry().voxelCount());
        } catch (const InputError& e) {
            throw InputError(run.scene().source, "method.params." + e.field(), e.problem(),
                             e.fix());
        }
        auto g = std::make_shared<const visibility::MultiresGrid>(
            pyr, visibility::selectLod(*pyr, tfa->tf, *tfa->table, budget));
        const std::size_t bytes = g->selection().level.size() * 5;
        return Artifact::of<visibility::MultiresGrid>(std::move(g), bytes);
    };
    grid.notOnDisk = "the LOD selection takes milliseconds";
    grid.describe = [](const Run& run, const Artifact& a) {
        const auto& s = a.as<visibility::MultiresGrid>()->selection();
        const auto voxels =
            run.get<visibility::BlockPyramid>("block_pyramid")->geometry().voxelCount();
        std::ostringstream os;
        os << s.points << " samples (1:" << (s.points ? double(voxels) / double(s.points) : 0.0)
           << "); blocks at 16^3/8^3/4^3/2^3/1^3/none: ";
        for (int l = 0; l <= visibility::kLevels; ++l)
            os << (l ? "/" : "") << s.blocksPerLevel[std::size_t(l)];
        return os.str();
    };
    plan.stages.push_back(grid);

    const visibility::LocalVisibilityOptions vo = params.visibility;
    json visKey = {
        {"rays", vo.rays}, {"coefficients", vo.coefficients}, {"radius", vo.radiusVoxels}};
    if (vo.algorithm == visibility::VisibilityAlgorithm::Sweep) visKey["algorithm"] = "sweep";
    Stage vis{"local_visibility",
              StageKind::Precompute,
              {"multires_grid", "transfer_function", "method"}};
    const auto visStageKey = [visKey](const Run& run) {
        return KeyBuilder(run, "local_visibility")
            .stage("multires_grid")
            .stage("transfer_function")
            .json(visKey)
            .value();
    };
    vis.key = visStageKey;
    // The lineage of a field: the same volume, rays, coefficients and radius (any TF).
    const auto localLineage = [visKey](const Run& run, const char* stage) {
        return KeyBuilder(run, std::string(stage) + "_lineage")
            .stage("block_pyramid")
            .json(visKey)
            .value();
    };
    vis.lineage = [localLineage](const Run& run) { return localLineage(run, "local_visibility"); };
    vis.compute = [vo, visKey, visStageKey](Run& run) {
        const auto tfa = run.get<TfArtifact>("transfer_function");
        const auto grid = run.get<visibility::MultiresGrid>("multires_grid");
        // A TF change on the same volume with the same rays, coefficients and radius starts from
        // the last field computed (if the cache still holds it) and recomputes only the blocks
        // the change reaches — the same field bit for bit (visibility/local_visibility.h).
        const std::optional<std::uint64_t> lineage =
            KeyBuilder(run, "local_visibility_lineage").stage("block_pyramid").json(visKey).value();
        std::shared_ptr<const visibility::LocalVisibility> previous;
        if (lineage)
            if (const auto k = run.cache().record("local_visibility_last", *lineage))
                if (const auto a = run.cache().findInMemory("local_visibility", *k))
                    previous = a->as<visibility::LocalVisibility>();
        visibility::TfUpdateStats st;
        std::shared_ptr<const visibility::LocalVisibility> v;
        try {
            v = std::make_shared<const visibility::LocalVisibility>(
                previous
                    ? visibility::updateLocalVisibility(*previous, grid, *tfa->table, vo,
                                                        run.progress(), &st)
                    : visibility::computeLocalVisibility(grid, *tfa->table, vo, run.progress()));
        } catch (const InputError& e) {
            rethrowAsScene(run.scene(), e);  // the sweep's anisotropy limit names the scene
        }
        if (const auto own = visStageKey(run); own && lineage)
            run.cache().putRecord("local_visibility_last", *lineage, *own, false);
        json d = {{"rays_traced", v->raysTraced()},
                  {"samples", v->samplesTaken()},
                  {"bytes", v->bytes()}};
        if (previous) {
            const auto bound = [](float x) { return std::isfinite(x) ? json(x) : json(nullptr); };
            d["tf_update"] = {
                {"incremental", st.incremental},
                {"reason", st.reason},
                {"sigma_changed_over",
                 st.changed.empty() ? json(nullptr)
                                    : json::array({bound(st.changed.lo), bound(st.changed.hi)})},
                {"blocks", st.blocks},
                {"blocks_level_changed", st.blocksLevelChanged},
                {"blocks_recomputed", st.blocksRecomputed},
                {"points", st.points},
                {"points_recomputed", st.pointsRecomputed}};
        }
        run.details()["local_visibility"] = d;
        const std::size_t bytes = v->bytes();
        return Artifact::of<visibility::LocalVisibility>(std::move(v), bytes);
    };
    vis.notOnDisk = "recomputed per transfer function; reading it back saves little";
    vis.describe = [](const Run& run, const Artifact& a) {
        const auto& v = *a.as<visibility::LocalVisibility>();
        std::ostringstream os;
        os << v.rays() << " rays, " << v.coefficients() << " SH coefficients, r_s "
           << v.radiusVoxels() << " voxels, " << (v.bytes() >> 20) << " MB";
        if (v.layerPoints() > 0) os << ", " << v.layerPoints() << " boundary-layer points";
        const json& u =
            run.details().value("local_visibility", json::object()).value("tf_update", json());
        if (u.is_object()) {
            if (u["incremental"].get<bool>())
                os << "; TF update: " << u["blocks_recomputed"].get<std::size_t>() << " of "
                   << u["blocks"].get<std::size_t>() << " blocks recomputed ("
                   << u["blocks_level_changed"].get<std::size_t>() << " at a new level)";
            else
                os << "; computed in full: " << u["reason"].get<std::string>();
        }
        return os.str();
    };
    plan.stages.push_back(vis);

    // The clip-aware update: keyed on the unclipped field and the removing planes alone.
    Stage clip{"clip_local_visibility",
               StageKind::Precompute,
               {"local_visibility", "transfer_function", "clip_planes", "crop_box"}};
    if (!cuts.any())
        clip.skip =
            "not needed: no clip plane or crop box removes matter for the light (none, or "
            "shadows_from_removed true)";
    clip.key = [cutKey = cuts.key](const Run& run) {
        return KeyBuilder(run, "clip_local_visibility")
            .stage("local_visibility")
            .stage("transfer_function")
            .json(cutKey)
            .value();
    };
    clip.lineage = [localLineage](const Run& run) {
        return localLineage(run, "clip_local_visibility");
    };
    clip.compute = [kept = cuts.kept, threads = vo.threads](Run& run) {
        const auto tfa = run.get<TfArtifact>("transfer_function");
        visibility::ClipUpdateStats st;
        auto v = std::make_shared<const visibility::LocalVisibility>(
            visibility::clipAwareLocalVisibility(
                *run.get<visibility::LocalVisibility>("local_visibility"), *tfa->table, kept,
                threads, run.progress(), &st));
        run.details()["clip_local_visibility"] = {{"blocks", st.blocks},
                                                  {"blocks_touched", st.blocksTouched},
                                                  {"points", st.points},
                                                  {"points_traced", st.pointsTraced},
                                                  {"points_cleared", st.pointsCleared},
                                                  {"rays_traced", st.raysTraced},
                                                  {"seconds", st.seconds}};
        const std::size_t bytes = v->bytes();
        return Artifact::of<visibility::LocalVisibility>(std::move(v), bytes);
    };
    clip.notOnDisk = "recomputed per clip plane position; only the points near a cut face";
    clip.describe = [](const Run& run, const Artifact&) {
        const json& d = run.details().value("clip_local_visibility", json::object());
        if (d.empty()) return std::string("clip-aware local visibility");
        std::ostringstream os;
        os << d["points_traced"].get<std::uint64_t>() << " of " << d["points"].get<std::uint64_t>()
           << " points traced again (" << d["points_cleared"].get<std::uint64_t>()
           << " cleared) in " << d["blocks_touched"].get<std::size_t>() << " of "
           << d["blocks"].get<std::size_t>() << " blocks";
        return os.str();
    };
    plan.stages.push_back(clip);
    if (!global) return;

    const visibility::GlobalVisibilityOptions go = params.global;
    const bool clipped = cuts.any();
    Stage gv{"global_visibility",
             StageKind::Precompute,
             {clipped ? "clip_local_visibility" : "local_visibility", "method"}};
    gv.key = [go, clipped](const Run& run) {
        return KeyBuilder(run, "global_visibility")
            .stage(clipped ? "clip_local_visibility" : "local_visibility")
            .integer(std::uint64_t(go.resolution))
            .integer(go.nearFromLocal ? 1 : 0)
            .integer(std::uint64_t(go.integration))
            .value();
    };
    gv.lineage = [go, clipped, visKey](const Run& run) {
        return KeyBuilder(run, "global_visibility_lineage")
            .stage("block_pyramid")
            .json(visKey)
            .integer(std::uint64_t(go.resolution))
            .integer(go.nearFromLocal ? 1 : 0)
            .integer(clipped ? 1 : 0)
            .integer(std::uint64_t(go.integration))
            .value();
    };
    gv.compute = [go, clipped](Run& run) {
        auto g = std::make_shared<const visibility::GlobalVisibility>(
            visibility::computeGlobalVisibility(lightLocalVisibility(run, clipped), go,
                                                run.progress()));
        run.details()["global_visibility"] = {
            {"rays_traced", g->raysTraced()},
            {"points_skipped", g->pointsSkipped()},
            {"bytes", g->bytes()},
            {"far_bytes", g->farBytes()},
            {"integration", g->integration() == visibility::GlobalIntegration::Recursive
                                ? "recursive"
                                : "piecewise"}};
        if (!g->integrationNote().empty())  // asked for recursive, ran piecewise: why
            run.details()["global_visibility"]["integration_note"] = g->integrationNote();
        const std::size_t bytes = g->bytes();
        return Artifact::of<visibility::GlobalVisibility>(std::move(g), bytes);
    };
    gv.notOnDisk = "recomputed per transfer function; reading it back saves little";
    gv.describe = [](const Run&, const Artifact& a) {
        const auto& g = *a.as<visibility::GlobalVisibility>();
        std::ostringstream os;
        os << g.resolution().x << "x" << g.resolution().y << "x" << g.resolution().z << " points, "
           << g.coefficients() << " SH coefficients, " << (g.bytes() >> 20) << " MB, "
           << (g.nearFromLocal() ? "near part from the local field" : "grid only")
           << (g.integration() == visibility::GlobalIntegration::Recursive ? ", recursive"
                                                                           : ", piecewise");
        return os.str();
    };
    plan.stages.push_back(gv);
}

/// block_pyramid ← volume (shared with sh-local/sh-global); opacity_pyramid ← pyramid + TF;
/// hierarchical_visibility ← opacity pyramid + rays/coefficients/patterns/subsample/quantize_8bit/
/// max_distance/hierarchical + seed; or, when a plane or the box removes matter for the light,
/// clip_hierarchical_visibility ← the same + the removing planes (the section-view ones are not
/// in its key). A light or camera change reruns none.
void addRitschelStages(Plan& plan, const visibility::HierarchicalVisibilityOptions& vo,
                       const LightCuts& cuts) {
    plan.stages.push_back(blockPyramidStage(false));

    Stage opacity{"opacity_pyramid", StageKind::Precompute, {"block_pyramid", "transfer_function"}};
    opacity.key = [](const Run& run) {
        return KeyBuilder(run, "opacity_pyramid")
            .stage("block_pyramid")
            .stage("transfer_function")
            .value();
    };
    opacity.compute = [](Run& run) {
        const auto tfa = run.get<TfArtifact>("transfer_function");
        core::Stopwatch sw;
        auto o = std::make_shared<const visibility::OpacityPyramid>(
            visibility::OpacityPyramid::build(*run.get<visibility::BlockPyramid>("block_pyramid"),
                                              tfa->tf, *tfa->table, run.progress()));
        run.details()["opacity_pyramid"] = {{"levels", o->levels()},
                                            {"seconds", sw.seconds()},
                                            {"memory_mb", double(o->bytes()) / 1048576.0}};
        const std::size_t bytes = o->bytes();
        return Artifact::of<visibility::OpacityPyramid>(std::move(o), bytes);
    };
    opacity.notOnDisk = "recomputed per transfer function in one pass over the voxels";
    opacity.describe = [](const Run&, const Artifact& a) {
        const auto& o = *a.as<visibility::OpacityPyramid>();
        return std::to_string(o.levels()) + " levels of product-minified extinction, " +
               std::to_string(o.bytes() >> 20) + " MB";
    };
    plan.stages.push_back(opacity);

    const json visKey = {
        {"rays", vo.rays},
        {"coefficients", vo.coefficients},
        {"patterns", vo.patterns},
        {"subsample", vo.subsample},
        {"quantize_8bit", vo.quantize8},
        {"hierarchical", vo.hierarchical},
        {"max_distance",
         std::isfinite(vo.maxDistanceVoxels) ? json(vo.maxDistanceVoxels) : json("volume")},
        {"seed", vo.seed}};
    Stage vis{"hierarchical_visibility", StageKind::Precompute, {"opacity_pyramid", "method"}};
    if (cuts.any())
        vis.skip =
            "not needed: a clip plane or the crop box removes matter for the light "
            "(shadows_from_removed false), and clip_hierarchical_visibility computes the field "
            "with it gone";
    vis.key = [visKey](const Run& run) {
        return KeyBuilder(run, "hierarchical_visibility")
            .stage("opacity_pyramid")
            .json(visKey)
            .value();
    };
    vis.lineage = [visKey](const Run& run) {
        return KeyBuilder(run, "hierarchical_visibility_lineage")
            .stage("block_pyramid")
            .json(visKey)
            .value();
    };
    vis.compute = [vo](Run& run) {
        core::Stopwatch sw;
        auto v = std::make_shared<const visibility::HierarchicalVisibility>(
            visibility::computeHierarchicalVisibility(
                run.get<visibility::OpacityPyramid>("opacity_pyramid"), vo, run.progress()));
        const double seconds = sw.seconds();
        run.details()["hierarchical_visibility"] = {
            {"rays_traced", v->raysTraced()},
            {"samples", v->samplesTaken()},
            {"points_skipped", v->pointsSkipped()},
            {"grid", {v->resolution().x, v->resolution().y, v->resolution().z}},
            {"seconds", seconds},
            {"rays_per_second", seconds > 0 ? double(v->raysTraced()) / seconds : 0.0},
            {"memory_mb", double(v->bytes()) / 1048576.0},
            {"quantize_8bit", v->quantized()}};
        const std::size_t bytes = v->bytes();
        return Artifact::of<visibility::HierarchicalVisibility>(std::move(v), bytes);
    };
    vis.notOnDisk = "recomputed per transfer function; reading it back saves little";
    vis.describe = [](const Run&, const Artifact& a) {
        const auto& v = *a.as<visibility::HierarchicalVisibility>();
        std::ostringstream os;
        os << v.rays() << " rays x " << v.patterns() << " patterns, " << v.coefficients()
           << " SH coefficients" << (v.quantized() ? " (8 bit)" : "") << ", 1:" << v.subsample()
           << " grid " << v.resolution().x << "x" << v.resolution().y << "x" << v.resolution().z
           << ", " << (v.bytes() >> 20) << " MB";
        return os.str();
    };
    plan.stages.push_back(vis);

    // The clip-aware field: the removed matter zeroed at the pyramid's base, the rays traced
    // again (they reach the whole volume, so a cut is not local; hierarchical_visibility.h).
    Stage clip{"clip_hierarchical_visibility",
               StageKind::Precompute,
               {"opacity_pyramid", "method", "clip_planes", "crop_box"}};
    if (!cuts.any())
        clip.skip =
            "not needed: no clip plane or crop box removes matter for the light (none, or "
            "shadows_from_removed true)";
    clip.key = [visKey, cutKey = cuts.key](const Run& run) {
        return KeyBuilder(run, "clip_hierarchical_visibility")
            .stage("opacity_pyramid")
            .json(visKey)
            .json(cutKey)
            .value();
    };
    clip.lineage = [visKey](const Run& run) {
        return KeyBuilder(run, "clip_hierarchical_visibility_lineage")
            .stage("block_pyramid")
            .json(visKey)
            .value();
    };
    clip.compute = [vo, kept = cuts.kept](Run& run) {
        core::Stopwatch sw;
        visibility::HierarchicalClipStats st;
        auto v = std::make_shared<const visibility::HierarchicalVisibility>(
            visibility::clipAwareHierarchicalVisibility(
                *run.get<visibility::OpacityPyramid>("opacity_pyramid"), kept, vo, run.progress(),
                &st));
        run.details()["clip_hierarchical_visibility"] = {
            {"voxels_removed", st.voxelsRemoved},
            {"pyramid_cells_changed", st.cellsChanged},
            {"points", st.points},
            {"points_traced", st.pointsTraced},
            {"points_cleared", st.pointsCleared},
            {"points_skipped", st.pointsSkipped},
            {"rays_traced", st.raysTraced},
            {"pyramid_seconds", st.pyramidSeconds},
            {"visibility_seconds", st.visibilitySeconds},
            {"seconds", sw.seconds()},
            {"memory_mb", double(v->bytes()) / 1048576.0}};
        const std::size_t bytes = v->bytes();
        return Artifact::of<visibility::HierarchicalVisibility>(std::move(v), bytes);
    };
    clip.notOnDisk = "recomputed per position of a plane that removes matter for the light";
    clip.describe = [](const Run& run, const Artifact&) {
        const json& d = run.details().value("clip_hierarchical_visibility", json::object());
        if (d.empty()) return std::string("clip-aware hierarchical visibility");
        std::ostringstream os;
        os << d["voxels_removed"].get<std::uint64_t>() << " voxels removed for the light; "
           << d["points_traced"].get<std::uint64_t>() << " of " << d["points"].get<std::uint64_t>()
           << " points traced (" << d["points_cleared"].get<std::uint64_t>()
           << " cleared on the removed side)";
        return os.str();
    };
    plan.stages.push_back(clip);
}

// ---- PVRT stages -------------------------------------------------------------------------------

/// What the photons score by default (pvrt/photons.h): "collision" or "track-length". The
/// track-length estimator scores every scattered photon along its whole onward flight; in thin
/// tissue, where a photon collides about once, that cut the NRMSE against the path tracer
/// (tools/bench_pvrt_accuracy.py) at 10 photons per boundary cell from 0.18/0.35/0.17 to
/// 0.10/0.25/0.12 (cloud / torso / abdominal CT), at 2.3–3.6× the photon stage's time per photon.
constexpr const char* kDefaultEstimator = "track-length";

/// Photons per boundary cell by default. With the collision estimator Zhang's 10 left the
/// indirect part blotchy on our data (optically thin tissue, where few photons collide in a
/// kernel's reach) and it took 100. The track-length estimator at 30 costs about what the
/// collision estimator did at 100 and is closer to the path tracer on all three benchmark
/// scenes (NRMSE 0.091/0.245/0.114 against 0.095/0.282/0.122).
constexpr int kDefaultPhotonsPerCell = 30;

/// Default budget of one PVRT transfer: a sixth of this kind of machine's 24 GB, so that the
/// direct transfer, its copy with the photons and the CPCA's working copy fit beside the volume.
constexpr double kDefaultPvrtMemoryMb = 4096.0;

/// pvrt's parameters (method.params): the basis of the lights, where transfer is stored, the
/// direct part's quadrature, the photons of the indirect part and the CPCA compression.
struct PvrtParams {
    std::string basis = "sh";
    int order = 4;         ///< SH order (basis sh): order² basis lights
    int directions = 162;  ///< DSF directions (basis dsf)
    int resolution = 64;   ///< transfer grid points per axis (capped at the volume's size)
    int quadrature = 162;  ///< directions of the direct part's transmittance sweeps
    /// SH coefficients of the incident radiance per basis light (pvrt/transfer.h): 1 = isotropic
    /// S (the default, today's transfer), 4/9/16 = view-dependent Henyey–Greenstein scattering.
    int exitance = 1;
    /// HG asymmetry (the path tracer's phase_g): the photons' scattering and, with exitance > 1,
    /// the render's in-scattering toward the eye; a TF phase g channel overrides it per sample.
    float phaseG = 0.f;
    /// exitance > 1: evaluate the coefficients toward the eye once per grid point at the light or
    /// camera change ("grid", pvrt::EyeFold; one RGB per point), or per sample in the frame
    /// ("sample": n RGB per point, no rerun on a camera move). "grid" needs CPCA (clusters > 0)
    /// and no TF phase g channel; otherwise it is per sample.
    bool evaluateAtGrid = true;
    bool multiple = true;  ///< the "multiple_scattering" effect with max_bounces > 1
    int maxBounces = 1;
    pvrt::PhotonOptions photons;
    int clusters = 128;  ///< CPCA clusters; 0 = uncompressed transfer
    int components = 4;
    int threads = 0;
    /// Largest transfer (MB) the precompute may build; the photon stage holds two (the direct
    /// one it copies and its own).
    double memoryMb = kDefaultPvrtMemoryMb;

    pvrt::Basis makeBasis() const {
        return basis == "sh" ? pvrt::Basis::sh(order) : pvrt::Basis::dsf(directions);
    }
    json directKey() const {
        return {{"basis", basis},           {"order", order},           {"directions", directions},
                {"resolution", resolution}, {"quadrature", quadrature}, {"exitance", exitance}};
    }
    json photonKey() const {
        return {{"photons", photons.photonsPerCell},
                {"kernel_radius", photons.kernelRadiusCells},
                {"max_scatterings", photons.maxScatterings},
                {"roulette_after", photons.rouletteAfter},
                {"estimator",
                 photons.estimator == pvrt::Estimator::TrackLength ? "track-length" : "collision"},
                {"seed", photons.seed},
                {"phase_g", photons.phaseG}};
    }
    json cpcaKey() const { return {{"clusters", clusters}, {"components", components}}; }
};

PvrtParams parsePvrtParams(const io::Scene& scene, const render::RenderOptions& o, ParamReader& p) {
    PvrtParams s;
    s.threads = o.threads;
    s.basis = p.choice("basis", "sh", {"sh", "dsf"});
    if (s.basis == "sh") {
        s.order = p.integer("order", 4, 1, pvrt::Basis::kMaxShOrder);
        if (p.has("directions"))
            p.fail("directions", "applies to basis 'dsf' only",
                   "remove it, or set basis to \"dsf\"");
    } else {
        s.directions = p.integer("directions", 162, 42, 642);
        if (s.directions != 42 && s.directions != 162 && s.directions != 642)
            p.fail("directions", "must be 42, 162 or 642, got " + std::to_string(s.directions),
                   "the DSF direction sets of a subdivided icosahedron");
        if (p.has("order"))
            p.fail("order", "applies to basis 'sh' only", "remove it, or set basis to \"sh\"");
    }
    // At least 2 points per axis: 1 is one point for the whole volume, read everywhere (a sphere
    // rendered 150× darker than at 32, probe). Below about 32 the error is large anyway (the
    // torso: 16 → 32 % relative RMS against 64, 32 → 16 %).
    s.resolution = p.integer("resolution", 64, 2, 1024);
    // DSF: the basis directions themselves by default (each feeds its own basis light exactly,
    // pvrt/direct.h); a coarser set would miss basis functions narrower than its spacing.
    const int dsfCount = s.basis == "dsf" ? s.directions : 0;
    s.quadrature = p.integer("quadrature", std::max(162, dsfCount), 42, 642);
    if (s.quadrature != 42 && s.quadrature != 162 && s.quadrature != 642)
        p.fail("quadrature", "must be 42, 162 or 642, got " + std::to_string(s.quadrature),
               "directions of the direct part's transmittance sweeps (icosahedral sets)");
    if (s.quadrature < dsfCount)
        p.fail("quadrature",
               std::to_string(s.quadrature) + " directions cannot integrate the " +
                   std::to_string(dsfCount) + " narrower basis functions of DSF-" +
                   std::to_string(dsfCount),
               "leave quadrature out (the DSF's own directions) or use at least " +
                   std::to_string(dsfCount));
    s.exitance = p.integer("exitance_coefficients", 1, 1, pvrt::kMaxExitance);
    if (!pvrt::validExitance(s.exitance))
        p.fail("exitance_coefficients", "must be 1, 4, 9 or 16, got " + std::to_string(s.exitance),
               "SH coefficients of the incident radiance (bands 0…3); 1 = isotropic scattering");
    s.phaseG = float(p.number("phase_g", 0.0, -0.99, 0.99));
    s.evaluateAtGrid = p.choice("exitance_evaluation", "grid", {"grid", "sample"}) == "grid";
    s.photons.phaseG = s.phaseG;
    s.maxBounces = parseMaxBounces(scene, p);
    s.multiple = s.maxBounces > 1;
    s.photons.maxScatterings = s.maxBounces - 1;
    // The photon pass only estimates multiple scattering: its settings under single scattering
    // were accepted and changed nothing (probe: photons 1 and 100000 gave the same image).
    for (const char* key : {"photons", "kernel_radius", "estimator"})
        if (!s.multiple && p.has(key))
            p.fail(key,
                   "applies only to multiple scattering (the photon pass), which this scene "
                   "does not simulate",
                   std::string("remove ") + key + ", or add \"multiple_scattering\" to effects");
    s.photons.photonsPerCell = p.integer("photons", kDefaultPhotonsPerCell, 1, 100000);
    s.photons.kernelRadiusCells = float(p.number("kernel_radius", 2.0, 0.5, 16.0));
    s.photons.estimator =
        p.choice("estimator", kDefaultEstimator, {"collision", "track-length"}) == "track-length"
            ? pvrt::Estimator::TrackLength
            : pvrt::Estimator::Collision;
    s.photons.seed = o.seed;
    s.photons.threads = o.threads;
    s.clusters = p.integer("clusters", 128, 0, 1 << 20);
    if (s.clusters == 0 && p.has("components"))
        p.fail("components", "applies only with CPCA (clusters > 0)",
               "remove it, or set clusters to e.g. 128");
    s.components = s.clusters > 0 ? p.integer("components", 4, 0, 64) : 0;
    s.memoryMb = p.number("memory_mb", kDefaultPvrtMemoryMb, 1.0, 1e7);
    return s;
}

const Codec& pvrtTransferCodec() {
    static const Codec c{
        2,
        [](const Artifact& a, ByteWriter& w) {
            const auto& t = *a.as<pvrt::Transfer>();
            w.pod(t.layout.res);
            w.pod(t.layout.scale);
            w.pod(t.layout.points);
            w.pod(t.basis);
            w.pod(t.exitance);
            w.array(t.layout.slot);
            w.array(t.values);
        },
        [](ByteReader& r) {
            auto t = std::make_shared<pvrt::Transfer>();
            t->layout.res = r.pod<glm::ivec3>();
            t->layout.scale = r.pod<glm::vec3>();
            t->layout.points = r.pod<std::int32_t>();
            t->basis = r.pod<int>();
            t->exitance = r.pod<int>();
            t->layout.slot = r.array<std::int32_t>(kMaxCells);
            t->values = r.array<float>(kMaxCells * 64 * pvrt::kMaxExitance);
            const glm::ivec3 res = t->layout.res;
            if (res.x < 1 || res.y < 1 || res.z < 1 || res.x > core::kMaxDim ||
                res.y > core::kMaxDim || res.z > core::kMaxDim || t->basis < 1 || t->basis > 4096 ||
                t->layout.points < 0 ||
                t->layout.slot.size() != std::size_t(res.x) * res.y * res.z ||
                !pvrt::validExitance(t->exitance) ||
                t->values.size() != std::size_t(t->layout.points) * t->basis * t->exitance * 3 ||
                !(t->layout.scale.x > 0.f && t->layout.scale.y > 0.f && t->layout.scale.z > 0.f))
                badPayload("PVRT transfer sizes do not fit together");
            std::int32_t next = 0;  // stored points are numbered in grid order
            for (std::int32_t s : t->layout.slot)
                if (s >= 0 && s != next++) badPayload("PVRT transfer slots out of order");
            if (next != t->layout.points) badPayload("PVRT transfer slot count");
            for (float v : t->values)
                if (!std::isfinite(v)) badPayload("non-finite PVRT transfer");
            const std::size_t bytes = t->bytes();
            return Artifact::of<pvrt::Transfer>(std::move(t), bytes);
        }};
    return c;
}

const Codec& pvrtCpcaCodec() {
    static const Codec c{
        1,
        [](const Artifact& a, ByteWriter& w) {
            const auto& p = *a.as<pvrt::Cpca>();
            w.pod(p.dim);
            w.pod(p.clusters);
            w.pod(p.components);
            w.pod(p.iterations);
            w.pod(p.relativeL2Error);
            w.array(p.means);
            w.array(p.basis);
            w.array(p.cluster);
            w.array(p.weights);
        },
        [](ByteReader& r) {
            auto p = std::make_shared<pvrt::Cpca>();
            p->dim = r.pod<int>();
            p->clusters = r.pod<int>();
            p->components = r.pod<int>();
            p->iterations = r.pod<int>();
            p->relativeL2Error = r.pod<double>();
            p->means = r.array<float>(kMaxCells);
            p->basis = r.array<float>(kMaxCells);
            p->cluster = r.array<std::int32_t>(kMaxCells);
            p->weights = r.array<float>(kMaxCells);
            const std::size_t rows = p->cluster.size();
            if (p->dim < 1 || p->clusters < 0 || p->components < 0 || p->components > 64 ||
                p->means.size() != std::size_t(p->clusters) * p->dim ||
                p->basis.size() != std::size_t(p->clusters) * p->components * p->dim ||
                p->weights.size() != rows * std::size_t(p->components) ||
                !std::isfinite(p->relativeL2Error))
                badPayload("CPCA sizes do not fit together");
            for (std::int32_t k : p->cluster)
                if (k < 0 || k >= p->clusters) badPayload("CPCA cluster index out of range");
            for (const auto* v : {&p->means, &p->basis, &p->weights})
                for (float x : *v)
                    if (!std::isfinite(x)) badPayload("non-finite CPCA value");
            const std::size_t bytes = p->bytes();
            return Artifact::of<pvrt::Cpca>(std::move(p), bytes);
        }};
    return c;
}

/// pvrt_direct ← volume + TF + skip cells + basis/resolution/quadrature + the cuts that remove
/// matter for the light; pvrt_transfer ← pvrt_direct + photons (skipped without multiple
/// scattering: the direct transfer is the transfer); pvrt_cpca ← the transfer + clusters/
/// components (skipped for clusters 0). A light or camera change reruns none of them: only the
/// Frame stage pvrt_radiance. Returns the name of the stage whose transfer the render reads.
std::string addPvrtStages(Plan& plan, const PvrtParams& params, const render::RenderOptions& o,
                          const LightCuts& cuts, bool tfPhaseChannel) {
    const json directKey = {{"params", params.directKey()}, {"cuts", cuts.key}};
    Stage direct{"pvrt_direct",
                 StageKind::Precompute,
                 {"skip_cells", "transfer_function", "method", "clip_planes", "crop_box"}};
    direct.key = [directKey](const Run& run) {
        return KeyBuilder(run, "pvrt_direct")
            .stage("load_volume")
            .stage("transfer_function")
            .stage("skip_cells")
            .json(directKey)
            .value();
    };
    direct.compute = [params, o](Run& run) {
        const core::Volume& v = run.get<LoadedVolume>("load_volume")->volume;
        const auto tfa = run.get<TfArtifact>("transfer_function");
        const auto cells = run.get<grid::BrickMajorants>("skip_cells");
        const pvrt::Basis basis = params.makeBasis();
        pvrt::TransferLayout layout;
        try {
            layout = pvrt::makeTransferLayout(v, *cells, params.resolution);
        } catch (const InputError& e) {
            rethrowAsScene(run.scene(), e);
        }
        // The budget before the allocation: a volume too large for the settings is a clear error,
        // not an out-of-memory kill.
        const double mb =
            double(layout.points) * basis.size() * params.exitance * 3 * sizeof(float) / 1048576.0;
        if (mb > params.memoryMb) {
            std::ostringstream os;
            os << "the transfer would take " << std::llround(mb) << " MB (" << layout.points
               << " points × " << basis.size() << " basis lights";
            if (params.exitance > 1) os << " × " << params.exitance << " exitance coefficients";
            os << " × RGB), over memory_mb " << params.memoryMb;
            // Named by the setting the scene (or a --set) lowered or raised: memory_mb under its
            // default, else the first of the sizes it gives (a --set memory_mb=1 was blamed on
            // the scene file's resolution).
            const json& given = run.scene().method.params;
            std::string field = "resolution";
            if (given.contains("memory_mb") && params.memoryMb < kDefaultPvrtMemoryMb)
                field = "memory_mb";
            else
                for (const char* k : {"resolution", "exitance_coefficients", "order", "directions"})
                    if (given.contains(k)) {
                        field = k;
                        break;
                    }
            throw InputError(run.scene().source, "method.params." + field, os.str(),
                             "lower resolution, use fewer basis lights (order, directions) or "
                             "exitance_coefficients, or raise method.params.memory_mb");
        }
        auto t = std::make_shared<pvrt::Transfer>(std::move(layout), basis.size(), params.exitance);
        pvrt::DirectOptions d;
        d.directions = params.quadrature;
        d.threads = params.threads;
        d.clipPlanes = o.clipPlanes;
        d.cropBox = o.cropBox;
        const pvrt::DirectStats st =
            pvrt::addDirectTransfer(v, *tfa->table, basis, *t, d, run.progress());
        run.details()["pvrt_direct"] = {{"basis", basis.name()},
                                        {"exitance_coefficients", t->exitance},
                                        {"transfer_mb", double(t->bytes()) / 1048576.0},
                                        {"points", t->layout.points},
                                        {"grid", dims(t->layout.res)},
                                        {"quadrature", st.directions},
                                        {"seconds", st.seconds}};
        const std::size_t bytes = t->bytes();
        return Artifact::of<pvrt::Transfer>(std::move(t), bytes);
    };
    // Kronander's interleaved update for PVRT too (RunOptions::staleFields): after a TF change or
    // a cut, the last transfer of the same volume and settings stands in (its radiance grid read
    // with the new classification) while the new one is computed.
    direct.lineage = [params](const Run& run) -> std::optional<std::uint64_t> {
        return KeyBuilder(run, "pvrt_direct_lineage")
            .stage("load_volume")
            .json(params.directKey())
            .value();
    };
    direct.codec = &pvrtTransferCodec();
    direct.describe = [](const Run&, const Artifact& a) {
        const auto& t = *a.as<pvrt::Transfer>();
        return std::to_string(t.layout.points) + " points of " + dims(t.layout.res) + " × " +
               std::to_string(t.basis) + " basis lights" +
               (t.exitance > 1 ? " × " + std::to_string(t.exitance) + " exitance coefficients"
                               : std::string()) +
               ", direct part, " + std::to_string(t.bytes() >> 20) + " MB";
    };
    plan.stages.push_back(direct);

    // Photons never scatter in removed matter, and section-view matter absorbs them on their way
    // in (photons.h): every plane and the crop box shape the indirect part, not only the cuts.
    // (Without section views the key is what it was, so earlier cached transfers still serve.)
    const json photonKey = {{"params", params.photonKey()}, {"cuts", cuts.key}};
    const json photonKeyed = cuts.sectionKey.empty()
                                 ? photonKey
                                 : json{{"photons", photonKey}, {"section_view", cuts.sectionKey}};
    Stage indirect{"pvrt_transfer",
                   StageKind::Precompute,
                   {"pvrt_direct", "method", "clip_planes", "crop_box"}};
    if (!params.multiple)
        indirect.skip =
            "not needed: single scattering (no 'multiple_scattering' effect or max_bounces 1)";
    indirect.key = [photonKeyed](const Run& run) {
        // The photons read the TF and the skip cells themselves: keyed on them as well as on the
        // direct part, which may be a stand-in of an earlier TF (RunOptions::staleFields) — then
        // this key is new and the lineage's last transfer stands in too, instead of photons
        // through the new TF being stored under the old direct part's key.
        return KeyBuilder(run, "pvrt_transfer")
            .stage("pvrt_direct")
            .stage("transfer_function")
            .stage("skip_cells")
            .json(photonKeyed)
            .value();
    };
    indirect.compute = [params, o](Run& run) {
        const auto loaded = run.get<LoadedVolume>("load_volume");
        const auto tfa = run.get<TfArtifact>("transfer_function");
        pathtrace::Options po;
        po.threads = params.threads;
        po.phaseG = params.phaseG;
        po.clipPlanes = o.clipPlanes;
        po.cropBox = o.cropBox;
        // The tracer shares the loaded volume (no copy): an aliasing pointer kept alive by it.
        const std::shared_ptr<const core::Volume> volume(loaded, &loaded->volume);
        const pathtrace::PathTracer medium(volume, tfa->table,
                                           run.get<grid::BrickMajorants>("skip_cells"), po);
        auto t = std::make_shared<pvrt::Transfer>(*run.get<pvrt::Transfer>("pvrt_direct"));
        const pvrt::PhotonStats st = pvrt::addIndirectTransfer(medium, params.makeBasis(), *t,
                                                               params.photons, run.progress());
        run.details()["pvrt_photons"] = {{"photons", st.photons},
                                         {"collisions", st.collisions},
                                         {"splats", st.splats},
                                         {"seconds", st.seconds}};
        const std::size_t bytes = t->bytes();
        return Artifact::of<pvrt::Transfer>(std::move(t), bytes);
    };
    indirect.lineage = [params](const Run& run) -> std::optional<std::uint64_t> {
        return KeyBuilder(run, "pvrt_transfer_lineage")
            .stage("load_volume")
            .json({{"direct", params.directKey()}, {"photons", params.photonKey()}})
            .value();
    };
    indirect.codec = &pvrtTransferCodec();
    indirect.describe = [](const Run& run, const Artifact& a) {
        const auto& t = *a.as<pvrt::Transfer>();
        const json& d = run.details().value("pvrt_photons", json::object());
        return "direct + indirect transfer of " + std::to_string(t.layout.points) + " points" +
               (d.empty() ? std::string()
                          : ", " + std::to_string(d["photons"].get<std::uint64_t>()) + " photons");
    };
    plan.stages.push_back(indirect);
    const std::string transferStage = params.multiple ? "pvrt_transfer" : "pvrt_direct";

    const json cpcaKey = params.cpcaKey();
    Stage cpca{"pvrt_cpca", StageKind::Precompute, {transferStage, "method"}};
    if (params.clusters == 0) cpca.skip = "not needed: clusters 0 (uncompressed transfer)";
    cpca.key = [cpcaKey, transferStage](const Run& run) {
        return KeyBuilder(run, "pvrt_cpca").stage(transferStage).json(cpcaKey).value();
    };
    cpca.compute = [params, transferStage](Run& run) {
        const auto t = run.get<pvrt::Transfer>(transferStage);
        pvrt::CpcaOptions co;
        co.clusters = params.clusters;
        co.components = params.components;
        co.seed = params.photons.seed;
        co.threads = params.threads;
        auto c = std::make_shared<pvrt::Cpca>(
            pvrt::compressCpca(t->values, int(t->rowSize()), co, run.progress()));
        run.details()["pvrt_cpca"] = {{"clusters", c->clusters},
                                      {"components", c->components},
                                      {"relative_l2_error", c->relativeL2Error},
                                      {"cpca_mb", double(c->bytes()) / 1048576.0}};
        const std::size_t bytes = c->bytes();
        return Artifact::of<pvrt::Cpca>(std::move(c), bytes);
    };
    cpca.codec = &pvrtCpcaCodec();
    // Clusters past the points were capped without a word (probe: 30000 on 23 840 points ran
    // 17.6 s of CPCA into 22 MB for a 4.5 MB transfer); said with every run, cached or not.
    cpca.warnings = [params](const Artifact& a) {
        const auto& c = *a.as<pvrt::Cpca>();
        std::vector<std::string> w;
        const double compressed = double(c.bytes()) / 1048576.0;
        const double plain = double(c.cluster.size()) * c.dim * sizeof(float) / 1048576.0;
        if (c.clusters < params.clusters || compressed >= plain) {
            std::ostringstream os;
            os << "method.params.clusters " << params.clusters;
            if (c.clusters < params.clusters)
                os << " is more than the transfer's " << c.cluster.size() << " points ("
                   << c.clusters << " clusters kept)";
            os << ": CPCA takes " << compressed << " MB against the uncompressed transfer's "
               << plain << " MB (use clusters 0 for no compression, or the default 128)";
            w.push_back(os.str());
        }
        return w;
    };
    cpca.describe = [](const Run&, const Artifact& a) {
        const auto& c = *a.as<pvrt::Cpca>();
        std::ostringstream os;
        os << c.clusters << " clusters × " << c.components << " components, relative L2 error "
           << 100.0 * c.relativeL2Error << " %";
        return os.str();
    };
    plan.stages.push_back(cpca);

    // Per light change: the lights (or the camera's headlight, when the scene has none) projected
    // into the basis and combined. Kept in memory, so a camera move under fixed lights reuses it.
    const bool compressed = params.clusters > 0;
    // n > 1 evaluated toward the eye per grid point: the camera and phase_g are inputs too —
    // unless the TF's phase channel sets g per rendered sample (the key below; its label here).
    const bool towardEye = params.exitance > 1 && params.evaluateAtGrid;
    Stage radiance{"pvrt_radiance",
                   StageKind::Precompute,
                   {transferStage, "pvrt_cpca", "lights",
                    towardEye && !tfPhaseChannel ? "camera" : "camera (headlight only)"}};
    radiance.key = [transferStage, compressed, towardEye, g = params.phaseG](const Run& run) {
        // A TF phase channel sets g per rendered sample: nothing is folded toward the eye then
        // (compute below), so the camera is no input (a preset never has the channel; explicit
        // points have it on all or none, TfPoint).
        const auto& points = run.scene().transferFunction.points;
        const bool fold = towardEye && (points.empty() || !points.front().phaseG);
        KeyBuilder k(run, "pvrt_radiance");
        k.stage(transferStage).stage("lights");
        if (compressed) k.stage("pvrt_cpca");
        if (run.scene().lights.empty() || fold) k.stage("camera");
        if (fold) k.json({{"toward_eye_phase_g", g}});
        return k.value();
    };
    radiance.notOnDisk = "recomputed per light change in milliseconds";
    radiance.compute = [params, transferStage, compressed, towardEye](Run& run) {
        const auto t = run.get<pvrt::Transfer>(transferStage);
        std::vector<std::shared_ptr<const lights::Light>> ls = *run.get<LightList>("lights");
        if (ls.empty())
            ls.push_back(render::headlight(*run.get<render::Camera>("camera"),
                                           render::kVolumetricHeadlightIrradiance));
        // The light change's time includes projecting the lights into the basis.
        core::Stopwatch sw;
        std::vector<glm::vec3> c;
        try {
            c = params.makeBasis().project(ls);
        } catch (const InputError& e) {
            rethrowAsScene(run.scene(), e);
        }
        // Toward the eye unless the TF's phase g channel sets g per rendered sample.
        std::optional<pvrt::EyeFold> eye;
        if (towardEye && !run.get<TfArtifact>("transfer_function")->table->hasPhaseG()) {
            const auto cam = run.get<render::Camera>("camera");
            eye =
                pvrt::EyeFold{.g = params.phaseG,
                              .geometry = run.get<LoadedVolume>("load_volume")->volume.geometry(),
                              .orthographic = cam->projection() == render::Projection::Orthographic,
                              .eye = cam->eye(),
                              .forward = cam->forward()};
        }
        std::shared_ptr<pvrt::RadianceVolume> r;
        if (compressed) {
            // Straight into the grid in the CPCA domain: no per-point buffer, empty points untouched.
            r = std::make_shared<pvrt::RadianceVolume>(
                pvrt::combineCpca(t->layout, *run.get<pvrt::Cpca>("pvrt_cpca"), c, t->exitance,
                                  params.threads, eye ? &*eye : nullptr));
        } else {
            r = std::make_shared<pvrt::RadianceVolume>(
                pvrt::combineTransfer(*t, c, params.threads, eye ? &*eye : nullptr));
        }
        run.details()["pvrt_radiance"] = {{"seconds", sw.seconds()},
                                          {"toward_eye", r->towardEye},
                                          {"clamped_points", r->clamped},
                                          {"radiance_mb", double(r->bytes()) / 1048576.0}};
        const std::size_t bytes = r->bytes();
        return Artifact::of<pvrt::RadianceVolume>(std::move(r), bytes);
    };
    radiance.describe = [](const Run& run, const Artifact& a) {
        const auto& r = *a.as<pvrt::RadianceVolume>();
        std::ostringstream os;
        os << "radiance volume " << dims(r.res);
        const json& d = run.details().value("pvrt_radiance", json::object());
        if (!d.empty()) os << " in " << 1e3 * d["seconds"].get<double>() << " ms";
        if (r.clamped) os << ", " << r.clamped << " points clamped at 0";
        return os.str();
    };
    plan.stages.push_back(radiance);
    return transferStage;
}

// ---- The plan ----------------------------------------------------------------------------------

/// iso-lattice's lattice (pipeline/iso_shading.h): the volume's float copy and skip bricks its
/// tracer reads, and the texels the frames fill. Lights are in the key except for an SH transfer
/// lattice, which re-dots when they change (the frame does).
Stage illuminationLatticeStage(const IsoLatticeParams& q, const render::RenderOptions& options) {
    const bool sh = q.lattice.mode == iso::LatticeMode::ShTransfer;
    Stage st{"illumination_lattice", StageKind::Precompute,
             sh ? std::vector<std::string>{"load_volume", "transfer_function", "method"}
                : std::vector<std::string>{"load_volume", "transfer_function", "lights", "method"}};
    if (!isoShadingTraces(q.shading.shading))
        st.skip = "not needed: shading 'phong' traces nothing";
    const json latticeKey = {
        {"samples", q.lattice.samples},
        {"bounces", q.lattice.bounces},
        {"resolution", q.lattice.resolution},
        {"mode", sh ? "sh" : "irradiance"},
        {"sh_order", q.lattice.shOrder},
        {"seed", q.lattice.seed},
        {"memory_mib", q.lattice.memoryBudgetMiB},
        {"texels", q.lattice.placement == iso::TexelPlacement::OnSurface ? "surface" : "own"},
        // the default isovalue is the TF's (its stage is in the key)
        {"iso_value", options.isoValue ? json(*options.isoValue) : json()},
        // What the cuts remove is gone for the light (shadows_from_removed false).
        {"light_cuts", lightCuts(options).key}};
    st.key = [latticeKey, sh](const Run& run) {
        KeyBuilder k(run, "illumination_lattice");
        k.stage("load_volume").stage("transfer_function").json(latticeKey);
        if (!sh) k.stage("lights");
        return k.value();
    };
    st.compute = [q, options](Run& run) {
        const auto loaded = run.get<LoadedVolume>("load_volume");
        LightList lights = *run.get<LightList>("lights");
        if (lights.empty()) lights.push_back(whiteSky());
        auto a = std::make_shared<LatticeArtifact>();
        const optics::TransferFunction& tf = run.get<TfArtifact>("transfer_function")->tf;
        iso::LatticeOptions lo = q.lattice;
        lo.keep = lightCuts(options).kept;
        try {
            if (lo.placement == iso::TexelPlacement::OnSurface)
                lo.surfaceIso = render::resolveIsoValue(tf, options);
            a->lattice = std::make_shared<iso::IlluminationLattice>(
                std::shared_ptr<const core::Volume>(loaded, &loaded->volume), tf, std::move(lights),
                lo);
        } catch (const InputError& e) {
            if (e.source() != "lattice") throw;
            static const std::map<std::string, std::string> param = {
                {"samples", "samples"},
                {"bounces", "bounces"},
                {"resolution", "lattice_resolution"},
                {"sh_order", "sh_order"},
                {"mode", "lattice_mode"},
                {"memory", "lattice_memory_mb"},
                {"isovalue", "iso_value"}};
            const auto it = param.find(e.field());
            throw InputError(run.scene().source,
                             it == param.end() ? e.field() : "method.params." + it->second,
                             e.problem(), e.fix());
        }
        a->lightsKey = lightsIdentity(run.scene());
        const std::size_t bytes = std::size_t(loaded->volume.voxelCount()) * sizeof(float);
        return Artifact::of<LatticeArtifact>(std::move(a), bytes);
    };
    st.notOnDisk = "texels are filled lazily by the frames that read them";
    st.describe = [](const Run&, const Artifact& a) {
        const auto& l = *a.as<LatticeArtifact>()->lattice;
        return std::to_string(l.dims().x) + "x" + std::to_string(l.dims().y) + "x" +
               std::to_string(l.dims().z) + " texels, " + std::to_string(l.texelsStored()) +
               " computed so far";
    };
    return st;
}

/// One iso-lattice frame: hits, the texels they read (lattice shading), the shading.
core::ImageRGBA renderIsoLatticeFrame(Run& run, const render::RayCaster& caster,
                                      const render::Camera& camera, const IsoLatticeParams& q,
                                      render::RenderStats& stats) {
    IsoShadingOptions o = q.shading;
    iso::IlluminationLattice* lattice = nullptr;
    if (run.has("illumination_lattice")) {
        const auto a = run.get<LatticeArtifact>("illumination_lattice");
        lattice = a->lattice.get();
        const std::uint64_t lk = lightsIdentity(run.scene());
        if (q.lattice.mode == iso::LatticeMode::ShTransfer && lk != a->lightsKey) {
            LightList lights = *run.get<LightList>("lights");
            if (lights.empty()) lights.push_back(whiteSky());
            try {
                lattice->setLights(std::move(lights));  // re-dots the texels: no tracing
            } catch (const InputError& e) {
                throw InputError(run.scene().source, "lights", e.problem(), e.fix());
            }
            a->lightsKey = lk;
        }
    }
    const core::Volume& v = caster.volume();
    o.vicinityRadiusMm = q.vicinityRadiusVoxels * core::minComponent(v.geometry().spacing);
    IsoFrameStats fs;
    core::ImageRGBA film;
    try {
        film = renderLitIsosurface(caster, camera, lattice, o, run.progress(), fs);
    } catch (const InputError& e) {
        if (e.source() != "lattice") throw;
        throw InputError(run.scene().source, "method.params.lattice_memory_mb", e.problem(),
                         e.fix());
    }
    stats.rays = fs.hits;
    stats.samples = fs.samples;
    json& d = run.details()["iso_lattice"];
    d["shading"] = isoShadingNames()[int(o.shading)];
    d["hit_pixels"] = fs.hits;
    d["hit_seconds"] = fs.hitSeconds;
    d["shade_seconds"] = fs.shadeSeconds;
    if (o.shading == IsoShading::Vicinity) d["vicinity_radius_mm"] = o.vicinityRadiusMm;
    if (o.shading == IsoShading::Lattice) {
        const iso::LatticeStats& ls = fs.lattice;
        d["lattice"] = {{"texels_full", ls.texelsFull},
                        {"texels_needed", ls.texelsNeeded},
                        {"texels_computed", ls.texelsComputed},
                        {"texels_reused", ls.texelsReused},
                        {"texels_stored", ls.texelsStored},
                        {"paths", ls.pathsTraced},
                        {"shadow_rays", ls.shadowRays},
                        {"plateau_texels", ls.plateauTexels},
                        {"seconds", ls.seconds},
                        {"stored_mib", ls.storedMiB},
                        {"tracer_mib", ls.tracerMiB},
                        {"skip_fields_built", ls.skipFieldsBuilt},
                        {"dims", {lattice->dims().x, lattice->dims().y, lattice->dims().z}}};
    }
    return film;
}

/// The load_volume artifact of `volume`, stored under the source's `identity` (its key).
Artifact loadedVolumeArtifact(ArtifactCache& cache, std::uint64_t identity,
                              std::shared_ptr<const core::Volume> volume) {
    auto v = std::make_shared<const LoadedVolume>(std::move(volume));
    // What a later process needs to name this volume's artifacts before reading it.
    cache.putRecord("volume-content", identity, v->contentHash);
    cache.putRecord("volume-voxels", identity, v->volume.voxelCount());
    const std::size_t bytes = v->volume.sizeBytes();
    return Artifact::of<LoadedVolume>(std::move(v), bytes);
}

/// What the image stage of a ray-caster method reads (Plan::casterSetup), from a run that has run
/// every stage before it.
CasterSetup casterSetupOf(const Run& run, const render::RenderOptions& options, Kind kind,
                          bool clipped) {
    CasterSetup c;
    const auto loaded = run.get<LoadedVolume>("load_volume");
    const auto tfa = run.get<TfArtifact>("transfer_function");
    c.volume = loaded->data;
    c.tf = std::shared_ptr<const optics::TransferFunction>(tfa, &tfa->tf);
    c.tables.table = tfa->table;
    c.tables.skipCells = run.get<grid::BrickMajorants>("skip_cells");
    if (run.has("gradients")) {
        const auto g = run.get<GradientArtifact>("gradients");
        c.tables.voxelGradients = g->dense;
        c.tables.brickedGradients = g->bricked;
    }
    c.options = options;
    if (run.has("lights")) c.options.lights = *run.get<LightList>("lights");
    if (run.has("light_sh")) c.options.irradianceSh = *run.get<std::vector<glm::vec3>>("light_sh");
    c.camera = run.get<render::Camera>("camera");
    if (kind == Kind::Ritschel) {
        c.sh.hierarchical = run.get<visibility::HierarchicalVisibility>(
            clipped ? "clip_hierarchical_visibility" : "hierarchical_visibility");
    } else if (isKronander(kind)) {
        c.sh.local = lightLocalVisibility(run, clipped);
        if (kind == Kind::ShGlobal) {
            // Local visibility within one global grid spacing of a removing face.
            c.sh.global = run.get<visibility::GlobalVisibility>("global_visibility");
            c.sh.cutBandMm = c.sh.global->spacingVoxels() *
                             float(core::minComponent(loaded->volume.geometry().spacing));
        }
    }
    return c;
}

Plan planRayCaster(Kind kind, const io::Scene& scene, ParamReader& reader) {
    checkPresetName(scene);  // named before the volume is loaded: refuse an unknown one now
    render::RenderOptions options = parseOptions(kind, scene, reader);
    std::optional<pathtrace::Options> traced;
    std::optional<pathtrace::DenoiseOptions> denoise;
    bool reference = false;
    if (kind == Kind::PathTrace) {
        traced = parsePathTraceOptions(scene, options, reader, reference);
        denoise = parseDenoiseParams(scene, options, reader, reference);
    }
    const ShParams shParams = isKronander(kind) ? parseShParams(kind, scene, reader) : ShParams{};
    const visibility::HierarchicalVisibilityOptions ritschelParams =
        kind == Kind::Ritschel ? parseRitschelParams(scene, reader)
                               : visibility::HierarchicalVisibilityOptions{};
    const PvrtParams pvrtParams =
        kind == Kind::Pvrt ? parsePvrtParams(scene, options, reader) : PvrtParams{};
    if (kind == Kind::Pvrt)
        for (std::size_t i = 0; i < scene.lights.size(); ++i)
            if (scene.lights[i].type != "directional" && scene.lights[i].type != "environment")
                throw InputError(scene.source, "lights[" + std::to_string(i) + "].type",
                                 std::string(scene.lights[i].type == "area" ? "an " : "a ") +
                                     scene.lights[i].type +
                                     " light is not distant: method 'pvrt' precomputes transfer "
                                     "for distant lighting only",
                                 "use directional or environment lights, or method 'sh-global' "
                                 "or 'pathtrace'");
    const IsoLatticeParams isoLattice =
        kind == Kind::IsoLattice ? parseIsoLatticeParams(scene, reader) : IsoLatticeParams{};
    if (kind == Kind::IsoLattice) {
        const IsoShading sh = isoLattice.shading.shading;
        if (sh == IsoShading::Lambert || sh == IsoShading::Shadows) {
            bool delta = false;
            for (const auto& l : scene.lights)
                delta = delta || l.type == "directional" || l.type == "point";
            if (!delta)
                throw InputError(scene.source, "method.params.shading",
                                 "'" + isoShadingNames()[int(sh)] +
                                     "' is lit by directional and point lights, and the scene "
                                     "has none",
                                 "add a directional or point light, or use shading 'lattice', "
                                 "'paths' or 'vicinity' (a white sky when the scene has no "
                                 "lights)");
        }
    }
    if (isSh(kind))
        options.shWindow =
            parseShWindowParams(reader, kind == Kind::Ritschel ? ritschelParams.coefficients
                                                               : shParams.visibility.coefficients);
    if (isSh(kind))
        for (std::size_t i = 0; i < scene.lights.size(); ++i)
            if (scene.lights[i].type == "area")
                throw InputError(scene.source, "lights[" + std::to_string(i) + "].type",
                                 "area lights are not shaded by method '" + scene.method.name + "'",
                                 "use directional, point or environment lights, or method "
                                 "'gradient'");
    Plan plan;
    plan.params = reader.used;
    const json optionsKey = {{"params", reader.used},
                             {"seed", options.seed},
                             {"termination", scene.render.termination},
                             {"background", scene.document.value("image", json::object())},
                             {"clip", scene.document.value("clip_planes", json::array())},
                             {"crop", scene.document.value("crop_box", json::object())}};
    // The skip rule: what makes a cell empty for this method.
    const json skipRule = {{"mode", int(options.mode)},
                           {"iso_value", options.isoValue ? json(*options.isoValue) : json()}};

    Stage load{"load_volume", StageKind::Input, {"volume"}};
    load.key = [](const Run& run) -> std::optional<std::uint64_t> {
        return volumeIdentity(run.scene());
    };
    load.compute = [](Run& run) {
        return loadedVolumeArtifact(
            run.cache(), volumeIdentity(run.scene()),
            std::make_shared<const core::Volume>(loadSceneVolume(run.scene(), run.progress())));
    };
    load.warnings = [](const Artifact& a) {  // e.g. a tilted series resampled
        return a.as<LoadedVolume>()->volume.warnings;
    };
    load.outputKey = [](const Run&, const Artifact& a) {
        return a.as<LoadedVolume>()->contentHash;
    };
    load.predictOutputKey = [](const Run& run, std::uint64_t identity) {
        return run.cache().record("volume-content", identity);
    };
    load.describe = [](const Run& run, const Artifact& a) {
        const auto& v = a.as<LoadedVolume>()->volume;
        const io::VolumeSource& src = run.scene().volume;
        return (src.phantom.empty() ? src.path.string() : "phantom '" + src.phantom + "'") + ", " +
               dims(v.dims()) + " " + std::string(core::toString(v.type()));
    };
    plan.stages.push_back(load);

    Stage brick{"brick_grid", StageKind::Precompute, {"load_volume"}};
    brick.key = [](const Run& run) {
        return KeyBuilder(run, "brick_grid").stage("load_volume").value();
    };
    brick.compute = [](Run& run) {
        auto g = std::make_shared<const grid::BrickGrid>(
            grid::BrickGrid::build(run.get<LoadedVolume>("load_volume")->volume, run.progress()));
        const std::size_t bytes = g->size() * sizeof(grid::BrickStats);
        return Artifact::of<grid::BrickGrid>(std::move(g), bytes);
    };
    brick.codec = &brickGridCodec();
    brick.describe = [](const Run&, const Artifact& a) {
        return std::to_string(a.as<grid::BrickGrid>()->size()) + " bricks of " +
               std::to_string(grid::kBrickSize) + "^3";
    };
    plan.stages.push_back(brick);

    const json tfDesc = scene.document.value("transfer_function", json());
    Stage tf{"transfer_function", StageKind::Precompute, {"load_volume", "transfer_function"}};
    // MIP/MinIP grey ramps choose their own window from the data unless the scene sets one.
    const int windowRule = scene.transferFunction.window ? 0
                           : kind == Kind::Mip           ? 1
                           : kind == Kind::MinIp         ? 2
                                                         : 0;
    tf.key = [tfDesc, windowRule](const Run& run) {
        return KeyBuilder(run, "transfer_function", kTfStageVersion)
            .stage("load_volume")
            .json(tfDesc)
            .integer(presetCatalogHash())
            .integer(windowRule)
            .value();
    };
    tf.compute = [kind, windowRule](Run& run) {
        auto t = std::make_shared<TfArtifact>();
        const core::Volume& volume = run.get<LoadedVolume>("load_volume")->volume;
        t->tf = buildTransferFunction(run.scene(), volume);
        if (windowRule != 0) t->tf = t->tf.withWindow(extremumWindow(kind, t->tf.window(), volume));
        t->table = std::make_shared<const optics::TfTable>(t->tf);
        return Artifact::of<TfArtifact>(std::move(t), kTfBytes);
    };
    tf.codec = &transferFunctionCodec();
    tf.describe = [](const Run&, const Artifact& a) {
        return "'" + a.as<TfArtifact>()->tf.name() + "'";
    };
    plan.stages.push_back(tf);

    // MIP/MinIP skip nothing and an explicit isovalue decides alone: their cells do not read the
    // TF, so a TF change keeps them.
    const bool cellsReadTf =
        !(kind == Kind::Mip || kind == Kind::MinIp ||
          ((kind == Kind::Iso || kind == Kind::IsoLattice) && options.isoValue.has_value()));
    Stage cells{"skip_cells", StageKind::Precompute,
                cellsReadTf ? std::vector<std::string>{"brick_grid", "transfer_function", "method"}
                            : std::vector<std::string>{"brick_grid", "method"}};
    cells.key = [skipRule, cellsReadTf](const Run& run) {
        KeyBuilder k(run, "skip_cells");
        k.stage("load_volume").json(skipRule);
        if (cellsReadTf) k.stage("transfer_function");
        return k.value();
    };
    cells.compute = [options](Run& run) {
        const auto tfa = run.get<TfArtifact>("transfer_function");
        std::shared_ptr<const grid::BrickMajorants> m;
        try {
            m = std::make_shared<const grid::BrickMajorants>(render::buildSkipCells(
                run.get<LoadedVolume>("load_volume")->volume,
                *run.get<grid::BrickGrid>("brick_grid"), tfa->tf, *tfa->table, options));
        } catch (const InputError& e) {
            rethrowAsScene(run.scene(), e);
        }
        const std::size_t bytes = m->size() * kSkipCellBytes;
        return Artifact::of<grid::BrickMajorants>(std::move(m), bytes);
    };
    cells.codec = &skipCellsCodec();
    cells.describe = [](const Run&, const Artifact& a) {
        const auto& m = *a.as<grid::BrickMajorants>();
        return std::to_string(m.nonEmptyCount()) + " of " + std::to_string(m.size()) +
               " skip cells (" + std::to_string(render::kSkipCellVoxels) + "^3) visible";
    };
    plan.stages.push_back(cells);

    // Gradients: which table depends on the volume's size, known only after loading; the key
    // names the choice so that dense and bricked tables never share one.
    Stage grad{"gradients", StageKind::Precompute, {"load_volume"}};
    if (kind != Kind::Gradient)
        grad.skip = "not needed: method '" + scene.method.name + "' reads no gradient table";
    else if (!options.centralDifferences)
        grad.skip = "not needed: forward differences (central_differences false) read no table";
    grad.key = [options](const Run& run) -> std::optional<std::uint64_t> {
        // Dense ← volume; bricked ← volume + skip cells. The choice needs the voxel count: from
        // the loaded volume, or (explain) from the record its last load left; unknown otherwise.
        std::uint64_t voxels = 0;
        if (run.has("load_volume")) {
            voxels = run.get<LoadedVolume>("load_volume")->volume.voxelCount();
        } else if (const auto v =
                       run.cache().record("volume-voxels", volumeIdentity(run.scene()))) {
            voxels = *v;
        } else {
            return std::nullopt;
        }
        const bool bricked =
            render::gradientTableUse(voxels, options) == render::GradientTableUse::Bricked;
        KeyBuilder k(run, "gradients");
        k.stage("load_volume").text(bricked ? "bricked" : "dense");
        if (bricked) k.stage("skip_cells");
        return k.value();
    };
    grad.compute = [options](Run& run) {
        const core::Volume& v = run.get<LoadedVolume>("load_volume")->volume;
        auto g = std::make_shared<GradientArtifact>();
        std::size_t bytes = 0;
        if (render::gradientTableUse(v, options) == render::GradientTableUse::Bricked) {
            g->bricked =
                std::make_shared<const render::BrickedGradients>(render::BrickedGradients::build(
                    v, *run.get<grid::BrickMajorants>("skip_cells"),
                    render::BrickedGradients::kMaxEntries, run.progress()));
            bytes = g->bricked->d.size() * sizeof(render::GradientEntry);
        } else {
            g->dense = std::make_shared<const render::VoxelGradients>(
                render::VoxelGradients::build(v, run.progress()));
            bytes = g->dense->d.size() * sizeof(render::GradientEntry);
        }
        return Artifact::of<GradientArtifact>(std::move(g), bytes);
    };
    // Not on disk: 8 bytes per voxel read back (0.95 s for 256³ on this kind of machine) cost
    // twice the pass that computes them (0.46 s).
    grad.notOnDisk = "recomputing is faster than reading 8 bytes per voxel back";
    grad.describe = [](const Run&, const Artifact& a) -> std::string {
        const auto& g = *a.as<GradientArtifact>();
        if (g.dense && !g.dense->empty()) return "dense central differences";
        if (g.bricked && !g.bricked->empty())
            return "bricked central differences near visible cells";
        return "no table (float volume or differences beyond int16): six taps per sample";
    };
    plan.stages.push_back(grad);

    const LightCuts cuts = lightCuts(options);
    const bool clipped = isSh(kind) && cuts.any();
    if (isKronander(kind)) addVisibilityStages(plan, shParams, kind == Kind::ShGlobal, cuts);
    if (kind == Kind::Ritschel) addRitschelStages(plan, ritschelParams, cuts);

    Stage lightsStage{"lights", StageKind::Input, {"lights"}};
    if (!isLit(kind)) lightsStage.skip = "not needed: method '" + scene.method.name + "' is unlit";
    lightsStage.key = [](const Run& run) -> std::optional<std::uint64_t> {
        return lightsIdentity(run.scene());
    };
    lightsStage.compute = [](Run& run) {
        auto l = std::make_shared<LightList>(buildLights(run.scene()));
        const std::size_t bytes = lightBytes(*l);
        return Artifact::of<LightList>(std::move(l), bytes);
    };
    // Lights that all emit nothing: a black picture said nothing (probe: an environment map at
    // intensity 0).
    const bool allDark =
        !scene.lights.empty() &&
        std::all_of(scene.lights.begin(), scene.lights.end(), [](const io::LightDesc& l) {
            return l.intensity == 0.0 || l.color == glm::dvec3(0.0);
        });
    if (allDark && isLit(kind))
        lightsStage.warnings = [](const Artifact&) {
            return std::vector<std::string>{
                "every light in the scene has intensity or color 0: only emission (and any "
                "ambient term) shows (raise lights[i].intensity)"};
        };
    const bool whiteSkyWhenNone =
        kind == Kind::IsoLattice && isoShadingTraces(isoLattice.shading.shading);
    lightsStage.describe = [whiteSkyWhenNone](const Run&, const Artifact& a) {
        const auto& l = *a.as<LightList>();
        if (l.empty())
            return std::string(whiteSkyWhenNone
                                   ? "none in the scene: a uniform white sky"
                                   : "none in the scene: a headlight follows the camera");
        std::string s;
        for (const auto& x : l) s += (s.empty() ? "" : ", ") + std::string(x->kind());
        return s;
    };
    plan.stages.push_back(lightsStage);

    Stage sh{"light_sh", StageKind::Precompute, {"lights"}};
    if (!isLit(kind))
        sh.skip = "not needed: method '" + scene.method.name + "' is unlit";
    else if (kind == Kind::PathTrace)
        sh.skip = "not needed: the path tracer samples environment maps directly";
    else if (isSh(kind))
        sh.skip = "not needed: " + scene.method.name +
                  " projects the lights' radiance SH itself, per frame";
    else if (kind == Kind::Pvrt)
        sh.skip = "not needed: pvrt projects the lights into its basis itself, per frame";
    else if (!hasEnvironmentLight(scene))
        sh.skip = "not needed: no environment light";
    // Keyed on the environment lights alone: moving a directional light re-projects no map.
    sh.key = [](const Run& run) {
        return KeyBuilder(run, "light_sh").integer(environmentLightsIdentity(run.scene())).value();
    };
    sh.compute = [](Run& run) {
        const auto l = run.get<LightList>("lights");
        auto e = std::make_shared<std::vector<glm::vec3>>(render::environmentIrradianceSh(*l));
        return Artifact::of<std::vector<glm::vec3>>(std::move(e), 9 * 12);
    };
    sh.codec = &irradianceCodec();
    sh.describe = [](const Run&, const Artifact&) {
        return std::string("irradiance SH, 9 coefficients");
    };
    plan.stages.push_back(sh);

    if (kind == Kind::IsoLattice)
        plan.stages.push_back(illuminationLatticeStage(isoLattice, options));

    // What the fitted camera frames: the hull of the visible matter (render/framing.h).
    // The cut's geometry only: whether removed matter still shadows does not change the framing.
    json cutDesc = {{"clip", json::array()}, {"crop", json::object()}};
    for (const render::ClipPlane& c : options.clipPlanes)
        cutDesc["clip"].push_back(
            {c.point.x, c.point.y, c.point.z, c.normal.x, c.normal.y, c.normal.z});
    if (options.cropBox)
        cutDesc["crop"] = {
            {"min", {options.cropBox->min.x, options.cropBox->min.y, options.cropBox->min.z}},
            {"max", {options.cropBox->max.x, options.cropBox->max.y, options.cropBox->max.z}}};
    const bool voxelsByTf = kind == Kind::Gradient || kind == Kind::EmissionAbsorption ||
                            kind == Kind::PathTrace || isSh(kind) || kind == Kind::Pvrt;
    // A camera the scene places whole (eye and target, and a perspective or an orthographic
    // height: render::Camera fits nothing then) is framed by nothing: the stage keys on the volume
    // alone and gives its box, so a cut or a TF edit under a placed camera (the viewer's, a
    // session's keyframes) reruns neither framing (≈ 70 ms on a 256³ volume) nor camera.
    const io::CameraDesc& cam = scene.camera;
    const bool placed = cam.eye && cam.target && cam.view != "auto" &&
                        (cam.projection != "orthographic" || cam.orthoHeight > 0.0);
    Stage framing{"framing", StageKind::Precompute,
                  placed       ? std::vector<std::string>{"load_volume"}
                  : voxelsByTf ? std::vector<std::string>{"skip_cells", "transfer_function",
                                                          "clip_planes", "crop_box"}
                               : std::vector<std::string>{"skip_cells", "clip_planes", "crop_box"}};
    framing.key = [cutDesc, voxelsByTf, placed](const Run& run) {
        KeyBuilder k(run, "framing");
        if (placed) return k.stage("load_volume").text("placed camera").value();
        k.stage("skip_cells").json(cutDesc);
        if (voxelsByTf) k.stage("transfer_function");
        return k.value();
    };
    framing.compute = [options, voxelsByTf, placed](Run& run) {
        const core::Volume& v = run.get<LoadedVolume>("load_volume")->volume;
        if (placed) {
            const std::array<glm::dvec3, 2> b = v.geometry().worldBounds();
            auto corners = std::make_shared<std::vector<glm::dvec3>>();
            for (int i = 0; i < 8; ++i)
                corners->push_back(
                    {i & 1 ? b[1].x : b[0].x, i & 2 ? b[1].y : b[0].y, i & 4 ? b[1].z : b[0].z});
            const std::size_t bytes = corners->size() * sizeof(glm::dvec3);
            return Artifact::of<std::vector<glm::dvec3>>(std::move(corners), bytes);
        }
        render::VoxelShows shows;
        if (voxelsByTf) {
            const auto tfa = run.get<TfArtifact>("transfer_function");
            const float widen = tfa->table->cellWidth();  // as the skip cells widen
            shows = [tfa, widen](float value) {
                return tfa->tf.maxExtinction(value - widen, value + widen) > 0.f;
            };
        }
        auto points = std::make_shared<const std::vector<glm::dvec3>>(
            render::framingPoints(v, *run.get<grid::BrickMajorants>("skip_cells"), shows,
                                  options.clipPlanes, options.cropBox));
        const std::size_t bytes = points->size() * sizeof(glm::dvec3);
        return Artifact::of<std::vector<glm::dvec3>>(std::move(points), bytes);
    };
    framing.notOnDisk = "recomputed from the skip cells in milliseconds";
    framing.describe = [placed](const Run&, const Artifact& a) {
        if (placed) return std::string("the volume's box (the scene places the camera)");
        return std::to_string(a.as<std::vector<glm::dvec3>>()->size()) +
               " hull points of the visible matter";
    };
    plan.stages.push_back(framing);

    const json cameraDesc = scene.document.value("camera", json::object());
    Stage camera{"camera", StageKind::Frame, {"framing", "camera", "image"}};
    camera.key = [cameraDesc](const Run& run) {
        const auto& im = run.scene().image;
        return KeyBuilder(run, "camera")
            .stage("framing")
            .json(cameraDesc)
            .number(im.width)
            .number(im.height)
            .value();
    };
    camera.compute = [kind](Run& run) {
        // Fitted to what the TF makes visible and the clip planes / crop box keep (clinical
        // viewers frame the anatomy, not the air), in this view's image plane.
        const std::vector<glm::dvec3>& points = *run.get<std::vector<glm::dvec3>>("framing");
        const io::Scene& s = run.scene();
        if (s.camera.apertureMm > 0.0 && kind != Kind::PathTrace)
            run.warn("camera.aperture: depth of field is rendered by method 'pathtrace' only; '" +
                     s.method.name + "' shows everything in focus");
        io::CameraDesc desc = s.camera;
        if (desc.view == "auto") {
            const io::NamedView* view = io::findView(resolveView(desc, points));
            desc.azimuthDeg = view->azimuthDeg, desc.elevationDeg = view->elevationDeg;
            desc.up = view->up;
            run.details()["camera_view"] = "auto: " + view->name;
        }
        try {
            auto c = std::make_shared<const render::Camera>(buildCameraSpec(desc), points,
                                                            s.image.width, s.image.height);
            const json& given = s.document.value("camera", json::object());
            if (c->upReplaced() && given.is_object() && given.contains("up")) {
                std::ostringstream os;
                os << "camera.up is parallel to the view direction; used [" << c->up().x << ", "
                   << c->up().y << ", " << c->up().z
                   << "] as the image's up (set camera.up or camera.roll to choose)";
                run.warn(os.str());
            }
            return Artifact::of<render::Camera>(std::move(c), sizeof(render::Camera));
        } catch (const InputError& e) {
            rethrowAsScene(s, e);
        }
    };
    plan.stages.push_back(camera);
    if (kind == Kind::Pvrt)
        addPvrtStages(plan, pvrtParams, options, cuts,
                      !scene.transferFunction.points.empty() &&
                          scene.transferFunction.points.front().phaseG.has_value());

    Stage frame{"render",
                StageKind::Frame,
                {"load_volume", "transfer_function", "skip_cells", "gradients", "camera", "lights",
                 "light_sh", "method", "render", "clip_planes", "crop_box", "image"}};
    if (isKronander(kind))
        frame.inputs.push_back(clipped ? "clip_local_visibility" : "local_visibility");
    if (kind == Kind::ShGlobal) frame.inputs.push_back("global_visibility");
    if (kind == Kind::IsoLattice) frame.inputs.push_back("illumination_lattice");
    if (kind == Kind::Pvrt) frame.inputs.push_back("pvrt_radiance");
    if (kind == Kind::Ritschel)
        frame.inputs.push_back(clipped ? "clip_hierarchical_visibility"
                                       : "hierarchical_visibility");
    frame.key = [optionsKey, kind, clipped](const Run& run) {
        KeyBuilder k(run, "render");
        k.stage("load_volume")
            .stage("transfer_function")
            .stage("skip_cells")
            .stage("gradients")
            .stage("camera")
            .stage("lights")
            .stage("light_sh");
        if (isKronander(kind)) k.stage(clipped ? "clip_local_visibility" : "local_visibility");
        if (kind == Kind::ShGlobal) k.stage("global_visibility");
        if (kind == Kind::IsoLattice) k.stage("illumination_lattice");
        if (kind == Kind::Pvrt) k.stage("pvrt_radiance");
        if (kind == Kind::Ritschel)
            k.stage(clipped ? "clip_hierarchical_visibility" : "hierarchical_visibility");
        return k.json(optionsKey).value();
    };
    if (kind == Kind::PathTrace) {
        if (!reference) {
            frame.compute = [pt = *traced, denoise](Run& run) {
                return publishTraced(run, *tracePath(run, pt, denoise));
            };
            plan.stages.push_back(frame);
            return plan;
        }
        // Reference mode: the traced image is a precomputed artifact (memory and disk cache), so
        // every method and test that measures itself against this scene traces it once.
        Stage ref = frame;
        ref.name = "reference";
        ref.kind = StageKind::Precompute;
        ref.key = [key = frame.key](const Run& run) { return key(run); };
        ref.compute = [pt = *traced](Run& run) {
            auto t = tracePath(run, pt);
            const std::size_t bytes = t->bytes();
            return Artifact::of<TracedImage>(std::move(t), bytes);
        };
        ref.codec = &tracedImageCodec();
        ref.describe = [](const Run&, const Artifact& a) {
            const auto& t = *a.as<TracedImage>();
            std::ostringstream os;
            const json& e = t.details["pathtrace"]["relative_std_error"];
            os << t.details["pathtrace"].value("spp", 0) << " spp, estimated error ";
            if (e.is_number())
                os << 100.0 * e.get<double>() << " %";
            else
                os << "unknown";  // one sample per pixel (null)
            return os.str();
        };
        plan.stages.push_back(ref);
        frame.inputs = {"reference"};
        frame.key = [](const Run& run) {
            return KeyBuilder(run, "render").stage("reference").value();
        };
        frame.compute = [](Run& run) {
            Artifact film = publishTraced(run, *run.get<TracedImage>("reference"));
            run.details()["denoise"] = {{"applied", false},
                                        {"reason", "reference renders are never denoised"}};
            return film;
        };
        plan.stages.push_back(frame);
        return plan;
    }
    plan.casterSetup = [options, kind, clipped](const Run& run) {
        return casterSetupOf(run, options, kind, clipped);
    };
    frame.compute = [options, kind, clipped, isoLattice, pvrtParams,
                     globalAsked = shParams.global.resolution,
                     radiusVoxels = shParams.visibility.radiusVoxels](Run& run) {
        const io::Scene& s = run.scene();
        const auto loaded = run.get<LoadedVolume>("load_volume");
        const auto tfa = run.get<TfArtifact>("transfer_function");
        const CasterSetup setup = casterSetupOf(run, options, kind, clipped);
        const render::RenderOptions& o = setup.options;
        const auto& camera = setup.camera;
        render::RenderStats stats;
        try {
            const render::RayCaster caster(setup.volume, setup.tf, o, setup.tables);
            core::Stopwatch sw;
            std::shared_ptr<core::ImageRGBA> film;
            if (isSh(kind)) {
                std::unique_ptr<render::ShadingModel> model;
                const CasterSetup::ShFields& f = setup.sh;
                if (kind == Kind::Ritschel)
                    model = render::makeShVisibilityModel(caster, *camera, f.hierarchical);
                else if (kind == Kind::ShLocal)
                    model = render::makeShVisibilityModel(caster, *camera, f.local);
                else
                    model = render::makeShVisibilityModel(caster, *camera, f.global, f.local,
                                                          f.cutBandMm);
                film = std::make_shared<core::ImageRGBA>(
                    caster.render(*camera, *model, run.progress(), &stats));
            } else if (kind == Kind::Pvrt) {
                const auto model = pvrt::makePvrtModel(
                    caster, *camera, run.get<pvrt::RadianceVolume>("pvrt_radiance"),
                    pvrtParams.phaseG, run.get<TfArtifact>("transfer_function")->table);
                film = std::make_shared<core::ImageRGBA>(
                    caster.render(*camera, *model, run.progress(), &stats));
            } else if (kind == Kind::IsoLattice) {
                film = std::make_shared<core::ImageRGBA>(
                    renderIsoLatticeFrame(run, caster, *camera, isoLattice, stats));
            } else {
                film = std::make_shared<core::ImageRGBA>(
                    caster.render(*camera, run.progress(), &stats));
            }
            const double seconds = sw.seconds();
            json& d = run.details();
            d["render"] = {{"step_voxels", o.stepVoxels},
                           {"step_mm", caster.stepMm()},
                           {"seed", o.seed},
                           {"termination", s.render.termination},
                           {"threads", o.threads}};
            // A resolved default is a parameter as used (pipeline.h: "params_resolved").
            if (kind == Kind::Iso || kind == Kind::IsoLattice)
                d["params_resolved"]["iso_value"] = caster.isoValue();
            // The global grid is capped at the multiresolution grid's points per axis: the
            // stats said 1024 where 64³ ran (probe).
            if (kind == Kind::ShGlobal && setup.sh.global) {
                const glm::ivec3 r = setup.sh.global->resolution();
                if (std::max({r.x, r.y, r.z}) != globalAsked)
                    d["params_resolved"]["global_resolution"] = {r.x, r.y, r.z};
                // Eq. 11 chains local visibility in steps of its radius between grid points:
                // points farther apart than that leave the far field between them unsampled (a
                // 1³ grid darkened the bonsai by a third, without a word; probe). In mm: the
                // radius counts the smallest spacing, a grid point spans dims/res voxels.
                const core::Geometry& g = loaded->volume.geometry();
                const double radiusMm = radiusVoxels * core::minComponent(g.spacing);
                double gapMm = 0.0;
                int fits = 2;
                for (int a = 0; a < 3; ++a) {
                    gapMm = std::max(gapMm, double(g.dims[a]) / double(r[a]) * g.spacing[a]);
                    fits =
                        std::max(fits, int(std::ceil(double(g.dims[a]) * g.spacing[a] / radiusMm)));
                }
                if (gapMm > radiusMm * (1.0 + 1e-9)) {
                    std::ostringstream os;
                    os << "method.params.global_resolution " << globalAsked
                       << " puts the global grid's points up to " << gapMm
                       << " mm apart, farther than the local visibility's radius (" << radiusMm
                       << " mm): the far field between them is guessed (raise global_resolution "
                          "to "
                       << fits << " or more)";
                    run.warn(os.str());
                }
            }
            const optics::TransferFunction& tfn = tfa->tf;
            json points = json::array();
            for (const auto& p : tfn.points())
                points.push_back({{"value", p.value},
                                  {"color", {p.color.r, p.color.g, p.color.b}},
                                  {"extinction", p.extinction}});
            d["transfer_function"] = {
                {"name", tfn.name()},
                {"window", {{"level", tfn.window().level}, {"width", tfn.window().width}}},
                {"points", points}};
            const core::Volume& vol = loaded->volume;
            d["volume"] = {{"dims", {vol.dims().x, vol.dims().y, vol.dims().z}},
                           {"type", std::string(core::toString(vol.type()))},
                           {"modality", std::string(core::toString(vol.modality))},
                           {"content_hash", core::hexKey(loaded->contentHash)}};
            if (loaded->nonFinite > 0)
                d["nonfinite_voxels"] = loaded->nonFinite;  // rendered as the TF's lowest value
            const render::Camera& cam = *camera;
            d["camera"] = cameraDetails(cam);
            d["counters"] = {
                {"rays", stats.rays},
                {"samples", stats.samples},
                {"rays_terminated_early", stats.terminatedEarly},
                {"samples_per_second", seconds > 0 ? double(stats.samples) / seconds : 0.0},
                {"skip_cells", stats.skipCells},
                {"skip_cells_visible", stats.skipCellsVisible}};
            if (isSh(kind)) {
                // The precomputed visibility looks from a sample to r_s, the volume's box or
                // beyond — never only as far as a point light: matter behind a light inside the
                // volume shadows it (a probe: a floor lit from between it and a dense ceiling read
                // 4× too dark under sh-global and ritschel; the path tracer's did not change).
                const auto box = vol.geometry().worldBounds();
                for (std::size_t i = 0; i < s.lights.size(); ++i) {
                    const glm::dvec3 p = s.lights[i].position;
                    if (s.lights[i].type == "point" && glm::all(glm::greaterThan(p, box[0])) &&
                        glm::all(glm::lessThan(p, box[1])))
                        run.warn("lights[" + std::to_string(i) +
                                 "] is a point light inside the volume: '" + s.method.name +
                                 "' takes its visibility past the light, so matter behind it "
                                 "casts shadows it should not ('pathtrace' traces its shadow "
                                 "rays to the light)");
                }
            }
            const grid::BrickGrid& bricks = *run.get<grid::BrickGrid>("brick_grid");
            // One line about the TF: the unit mismatch explains an empty image too — except under
            // the iso methods, whose surface the isovalue places (the TF only colours it): an
            // empty iso image says why as well (a plane removing everything showed only the HU
            // line).
            const bool iso = kind == Kind::Iso || kind == Kind::IsoLattice;
            if (!warnIfNotHounsfield(run, tfn, bricks) || iso)
                warnIfNothingShows(run, kind, *film, stats, tfn, bricks, caster.isoValue());
            // At or below every value the whole volume is inside the surface: its box, drawn
            // without a word (`voxlight iso` refuses such an isovalue).
            if (iso && caster.isoValue() <= bricks.valueLo()) {
                std::ostringstream os;
                os << "method.params.iso_value " << caster.isoValue()
                   << " is at or below every value of this volume [" << bricks.valueLo() << ", "
                   << bricks.valueHi()
                   << "]: the whole volume is inside the surface, drawn as its box (set "
                      "method.params.iso_value inside the values)";
                run.warn(os.str());
            }
            const std::size_t bytes = film->pixels.size() * sizeof(float);
            return Artifact::of<core::ImageRGBA>(std::move(film), bytes);
        } catch (const InputError& e) {
            rethrowAsScene(s, e);
        }
    };
    frame.describe = [kind](const Run& run, const Artifact& a) {
        const auto& img = *a.as<core::ImageRGBA>();
        return run.scene().method.name + " " + std::to_string(img.width) + "x" +
               std::to_string(img.height);
    };
    plan.stages.push_back(frame);
    return plan;
}

MethodInfo rayCasterMethod(Kind kind, std::string name, std::string summary,
                           std::vector<std::string> extraParams, std::vector<std::string> effects) {
    MethodInfo m;
    m.name = std::move(name);
    m.summary = std::move(summary);
    m.effects = std::move(effects);
    std::vector<std::string> allowed = {"step", "preintegrated", "empty_space_skipping",
                                        "early_termination", "jitter"};
    allowed.insert(allowed.end(), extraParams.begin(), extraParams.end());
    m.params = allowed;
    m.plan = [kind](const io::Scene& scene, ParamReader& reader) {
        return planRayCaster(kind, scene, reader);
    };
    return m;
}

const RegisterMethod kEmissionAbsorption(
    rayCasterMethod(Kind::EmissionAbsorption, "emission-absorption",
                    "σt, albedo and emission from the TF under uniform unit light, no visibility",
                    {"ambient"}, {}));
const RegisterMethod kGradient(rayCasterMethod(
    Kind::Gradient, "gradient", "gradient Blinn–Phong without visibility (the clinical baseline)",
    {"ambient", "diffuse", "specular", "shininess", "central_differences"}, {"specular"}));
const RegisterMethod kMip(rayCasterMethod(Kind::Mip, "mip",
                                          "maximum intensity projection, grey through the window",
                                          {}, {}));
const RegisterMethod kMinIp(rayCasterMethod(Kind::MinIp, "minip",
                                            "minimum intensity projection, grey through the window",
                                            {}, {}));
const RegisterMethod kPathTrace([] {
    MethodInfo m;
    m.name = "pathtrace";
    m.summary =
        "Monte-Carlo path tracer: delta tracking over the majorant grid, exact shadows, "
        "single or multiple scattering (the reference)";
    m.effects = {"local_shadows", "global_shadows", "multiple_scattering"};
    m.params = {"spp",      "seconds",    "target_error",    "reference",     "max_bounces",
                "phase_g",  "scattering", "gradient_factor", "majorant_grid", "antialias",
                "adaptive", "denoise",    "denoise_target"};
    m.plan = [](const io::Scene& scene, ParamReader& reader) {
        return planRayCaster(Kind::PathTrace, scene, reader);
    };
    return m;
}());
const RegisterMethod kShLocal(rayCasterMethod(
    Kind::ShLocal, "sh-local",
    "SH local visibility on a multiresolution grid (Kronander 2012): soft self-shadowing "
    "within "
    "a radius under directional, point and environment lights",
    {"rays", "coefficients", "radius", "algorithm", "data_reduction", "lod_budget_mb", "window",
     "window_strength", "ambient", "near_shadow", "near_trace"},
    {"local_shadows"}));
const RegisterMethod kShGlobal(rayCasterMethod(
    Kind::ShGlobal, "sh-global",
    "SH global visibility (Kronander 2012 eq. 11): local visibility chained in steps of its "
    "radius "
    "on a regular grid; shadows from matter anywhere toward the light",
    {"rays", "coefficients", "radius", "algorithm", "data_reduction", "lod_budget_mb",
     "global_resolution", "global_near", "global_integration", "window", "window_strength",
     "ambient", "near_shadow", "near_trace"},
    {"local_shadows", "global_shadows"}));
const RegisterMethod kRitschel(rayCasterMethod(
    Kind::Ritschel, "ritschel",
    "hierarchical SH visibility (Ritschel 2007): rays with growing steps through a "
    "product-minified extinction pyramid, to the volume's boundary, on a 1:s grid; shadows "
    "from matter anywhere toward the light",
    {"rays", "coefficients", "patterns", "subsample", "quantize_8bit", "max_distance",
     "hierarchical", "window", "window_strength", "ambient"},
    {"local_shadows", "global_shadows"}));
const RegisterMethod kIsoLattice(rayCasterMethod(
    Kind::IsoLattice, "iso-lattice",
    "direct isosurface shaded with global illumination from Wyman's illumination lattice "
    "(lazy texels, shadows, sky, interreflections), or one of his baselines for comparison",
    {"iso_value", "shading", "samples", "bounces", "lattice_resolution", "lattice_mode", "sh_order",
     "lattice_memory_mb", "lattice_texels", "vicinity_radius", "ambient", "diffuse", "specular",
     "shininess"},
    {}));
const RegisterMethod kPvrt(rayCasterMethod(
    Kind::Pvrt, "pvrt",
    "precomputed volume radiance transfer (Zhang 2013): single and multiple scattering under "
    "dynamic distant lights through SH or DSF basis lights, photon-mapped indirect light, CPCA",
    {"basis", "order", "directions", "resolution", "quadrature", "exitance_coefficients", "phase_g",
     "exitance_evaluation", "max_bounces", "photons", "kernel_radius", "estimator", "clusters",
     "components", "memory_mb"},
    {"local_shadows", "global_shadows", "multiple_scattering"}));
const RegisterMethod kIso(rayCasterMethod(
    Kind::Iso, "iso", "direct isosurface: first crossing of the isovalue, Lambertian",
    {"iso_value", "ambient", "diffuse"}, {}));

}  // namespace

std::shared_ptr<const core::Volume> adoptVolume(Session& session, const io::Scene& scene,
                                                std::shared_ptr<const core::Volume> volume) {
    VL_CHECK(volume != nullptr);
    const std::uint64_t identity = volumeIdentity(scene);
    session.cache().putInMemory("load_volume", identity,
                                loadedVolumeArtifact(session.cache(), identity, volume));
    return volume;
}

}  // namespace voxlight::pipeline
