// SPDX-License-Identifier: MIT
#pragma once
// What accuracy costs in time (issue #17 item 2): a sweep is one scene, its path-traced reference,
// and parameter axes per method; each scene variant is rendered through the pipeline and measured
// against the reference (image_metrics.h) beside what it cost.
//
// The sweep file (JSON; docs/sweeps.md has the reference):
//   {
//     "name": "torso-sh",                        // optional; default: the file's stem
//     "scene": "torso.json" | { ...scene... },   // a scene file (relative to the sweep file) or
//                                                // an inline scene (paths relative to the sweep)
//     "overrides": ["image.width=96", ...],      // optional, applied to the scene (as --set)
//     "reference": {"params": {"reference": true}, "effects": ["global_shadows"]},  // pathtrace
//                                                // ("method" too: default pathtrace)
//     "frames": 3,                               // frames timed per variant (median), 1..100
//     "runs": [
//       {"method": "sh-local", "label": "sh-local", "params": {...}, "effects": [...],
//        "axes": {"rays": [16, 64, 256], "coefficients": [1, 4, 9, 16]},
//        "combine": "one-at-a-time" | "grid",
//        "reference": {"method": "iso-lattice", "params": {"shading": "paths"}}},  // optional:
//                                                // this run's own reference (another model)
//       {"method": "gradient"}                   // no axes: one variant (a baseline)
//     ]
//   }
// "one-at-a-time" (the default) varies each axis alone from `params` (the base), in the order the
// axes are written, and adds the base itself once first; "grid" takes every combination. Every
// variant's scene is validated and planned (params parsed strictly) before anything renders: a bad
// sweep is one InputError naming the file and the key ("runs[2].axes.rays[1]").
//
// Costs. All variants run through one pipeline session, so a stage two variants share (the volume,
// the TF tables, one local visibility field for sh-local and sh-global) is computed once; but each
// variant is charged the full cost of every precompute stage it reads — the seconds the stage took
// when this sweep computed it — so `precompute_s` is what the variant costs from cold (minus
// reading the volume file), whatever ran before it. `frame_s` is the median of `frames` renders of
// the image stage. `memory_mb` is the size of the precomputed artifacts the frame reads.
//
// Errors, against the reference (same scene, method pathtrace; cached on disk by the pipeline):
//   nrmse        linear radiance, relative RMSE over pixels either image covers (ErrorStats::nrmse)
//   rmse_255     display images (the scene's display transform and exposure), RMSE in 1/255 steps
//   psnr_db      display images, peak 1
//   ssim         display images (mean SSIM over covered pixels)
//   flip         display images (mean LDR-FLIP over covered pixels)
//   detected     fraction of covered pixels with FLIP above 0.05 (detectionFraction)
// The reference's own noise in nrmse's terms (its `expected_nrmse`: √(Σ variance / Σ mean²) over
// covered pixels and RGB) is the floor no variant's nrmse can be expected to fall below (a
// perfect method's nrmse² against it is that value squared); the CSV carries it on every row as
// `reference_error` (nan when the reference is not the path tracer's). Until 7 December the
// column held the tracer's `relative_std_error`, normalised by the mean luminance rather than the
// RMS value: a floor 1.4–1.5× too high on the convergence benchmark's images. A run with its own "reference" (the isosurface methods: the
// path tracer renders the volume, not the surface) is measured against that one; the CSV's last
// column says which (0 = the sweep's).
//
// Determinism: the errors are those of deterministic renders (fixed seeds), so they repeat
// exactly for any thread count or distribution of the variants; the seconds do not.
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "analysis/image_metrics.h"
#include "core/image.h"
#include "core/progress.h"
#include "io/scene.h"
#include "pipeline/pipeline.h"

namespace voxlight::analysis {

/// Most variants one sweep expands to (a grid of many axes grows fast).
inline constexpr std::size_t kMaxSweepVariants = 10000;
/// Most frames timed per variant.
inline constexpr int kMaxSweepFrames = 100;
/// FLIP value above which a pixel counts as a detected difference (DetectionOptions' default).
inline constexpr double kSweepDetectionThreshold = 0.05;

/// A reference image's render: method, params, effects (the sweep's scene otherwise).
struct SweepReferenceSpec {
    std::string method = "pathtrace";
    nlohmann::json params = {{"reference", true}};
    /// Unset: the scene's (a reference of another method than pathtrace without "effects").
    std::optional<std::vector<std::string>> effects = std::vector<std::string>{"global_shadows"};
    bool operator==(const SweepReferenceSpec&) const = default;
};

struct SweepRun {
    std::string label;                                 ///< "label", default the method's name
    std::string method;                                ///< a registered method
    nlohmann::json params = nlohmann::json::object();  ///< the base
    std::optional<std::vector<std::string>> effects;   ///< unset: the scene's
    std::vector<std::pair<std::string, std::vector<nlohmann::json>>> axes;  ///< in file order
    bool grid = false;                                                      ///< "combine": "grid"
    std::size_t reference = 0;  ///< index into SweepSpec::references
};

struct SweepSpec {
    std::string source;  ///< the sweep file's name, for errors
    std::string name;
    nlohmann::json scene;            ///< the scene document, overrides applied
    std::filesystem::path sceneDir;  ///< relative paths in `scene` resolve against it
    /// [0] the sweep's reference; runs with their own add theirs (identical ones shared).
    std::vector<SweepReferenceSpec> references = {SweepReferenceSpec{}};
    int frames = 1;
    std::vector<SweepRun> runs;
};

/// Validates a sweep document; relative paths resolve against `baseDir`. InputError naming
/// `source` and the key on any problem.
SweepSpec parseSweep(const nlohmann::json& doc, const std::string& source,
                     const std::filesystem::path& baseDir);
/// Reads and validates a sweep file (io::readJsonFile's checks, then parseSweep).
SweepSpec loadSweep(const std::filesystem::path& path);

/// One scene variant: a unit of work.
struct SweepItem {
    std::size_t index = 0;  ///< position in the expansion (the CSV's row order)
    std::string id;         ///< unique, file-name safe: "sh-local-rays-64", "pvrt-grid-003"
    std::string label, method;
    std::string axis;       ///< the axis varied ("" for a base or a grid point)
    nlohmann::json value;   ///< its value (null for a base or a grid point)
    nlohmann::json params;  ///< the variant's full params
    std::optional<std::vector<std::string>> effects;
    std::size_t reference = 0;  ///< index into SweepSpec::references
};

/// Every variant of the sweep in order (runs in file order; see the header comment).
std::vector<SweepItem> expandSweep(const SweepSpec& spec);

/// The variant's scene, parsed (InputError naming the sweep, the run and the key when invalid).
io::Scene variantScene(const SweepSpec& spec, const SweepItem& item);
/// Reference `index`'s scene: its method, params and effects on the sweep's scene.
io::Scene referenceScene(const SweepSpec& spec, std::size_t index = 0);
/// Parses and plans every variant and the reference without rendering (strict params).
void validateSweep(const SweepSpec& spec, const std::vector<SweepItem>& items,
                   const pipeline::Session& session);

struct SweepReference {
    core::ImageRGBA linear;       ///< radiance, alpha = coverage
    core::ImageRGBA display;      ///< the scene's display transform
    double relativeStdError = 0;  ///< the path tracer's estimate of its own relative error
    /// Its noise in ErrorStats::nrmse's terms (pathtrace::Stats::expectedNrmse; nan when the
    /// reference is not the path tracer's or was cached before the tracer reported it).
    double expectedNrmse = 0;
    long long spp = 0;
    double seconds = 0;  ///< what it took now (0 when served from the cache)
    bool cached = false;
    /// The reference render's warnings (e.g. stopped above its target error): every row is
    /// measured against it, so the sweep repeats them (they were dropped without a word).
    std::vector<std::string> warnings;
};

struct SweepRow {
    SweepItem item;
    double precomputeSeconds = 0, frameSeconds = 0, memoryMb = 0;
    double nrmse = 0, rmse255 = 0, psnrDb = 0, ssim = 0, flip = 0, detected = 0;
    double referenceError = 0;  ///< SweepReference::expectedNrmse (nan: not estimated)
    std::vector<std::string> warnings;
};

/// What one variant produced besides its numbers: its display image and FLIP error map.
struct SweepImages {
    core::ImageRGBA display;
    core::ImageRGBA errorMap;  ///< FLIP, magma, 0..kSweepMapMax
};
/// FLIP value at the bright end of the error maps: differences beyond it look alike.
inline constexpr float kSweepMapMax = 0.5f;

/// Runs variants against the reference. Holds the cost of every precompute artifact it has seen
/// computed, so a variant reading a shared artifact is charged its full cost (header comment).
class SweepRunner {
  public:
    /// `variants` renders the variants (memory cache only, so costs are this process's);
    /// `references` the reference (give it a disk cache directory to keep references across runs).
    SweepRunner(const SweepSpec& spec, pipeline::Session& variants, pipeline::Session& references);
    /// Reference `index` (rendered on first use).
    const SweepReference& reference(std::size_t index = 0,
                                    const core::Progress& progress = core::Progress::none());
    /// Renders one variant and measures it. `images`, when given, receives its pictures.
    SweepRow run(const SweepItem& item, const core::Progress& progress = core::Progress::none(),
                 SweepImages* images = nullptr);
    /// Called after every stage of the reference and variant runs (pipeline::RunOptions).
    void setAfterStage(std::function<void(const pipeline::StageRecord&)> hook) {
        afterStage_ = std::move(hook);
    }

  private:
    const SweepSpec& spec_;
    pipeline::Session& variants_;
    pipeline::Session& references_;
    std::map<std::size_t, SweepReference> references_done_;
    std::function<void(const pipeline::StageRecord&)> afterStage_;
    std::map<std::string, double> cost_;  ///< "stage:key" → seconds when computed
};

/// The CSV's header line and one row (no newline). Columns: index, id, label, method, axis,
/// value, params (compact JSON), precompute_s, frame_s, memory_mb, nrmse, rmse_255, psnr_db,
/// ssim, flip, detected, reference_error, reference (index). Fields with commas or quotes are quoted (RFC 4180).
std::string sweepCsvHeader();
std::string sweepCsvRow(const SweepRow& row);

}  // namespace voxlight::analysis
