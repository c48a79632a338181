// SPDX-License-Identifier: MIT
#pragma once
// Scene → plan of stages → run with a cache: "simulate only what the scene calls for".
//
// A method (registry.h) turns a scene into a Plan: an ordered list of Stages. Each stage declares
// what it reads (`inputs`, for people) and computes its key from exactly those (`key`, for the
// cache): the keys of the earlier stages it reads plus its own settings. So
//   load_volume      ← the volume's source (file identity: path, size, mtime; or phantom + size);
//                      its *output* key is the content hash of what it loaded
//   brick_grid       ← volume content
//   transfer_function← volume content (relative presets fit its range) + the scene's TF
//   skip_cells       ← volume + TF + the method's skip rule
//   gradients        ← volume (dense) or volume + skip cells (bricked)
//   lights, light_sh ← the scene's lights (+ each environment map file's identity)
//   camera           ← skip cells (a fitted camera frames what the TF makes visible) + camera + image
//   render           ← all of the above
// Stage kinds: Input (reads files; cached in memory only), Precompute (memory, and disk when the
// stage has a Codec and a cache directory is set) and Frame (run every frame, never cached). A
// stage the scene does not need stays in the plan with `skip` = why ("not needed: no environment
// light"), so the stats say what was *not* simulated, and why.
//
// Running: each stage in order — not needed → recorded as such; else its key; memory cache hit →
// "cached <key>"; disk hit → "cached <key> (disk)"; else computed (and stored). explain() walks the
// same plan without computing and says what run() would do; it agrees with run() except when a
// volume file's content hash is not yet known (first sight of that file), where it says
// "computed (volume not read before)" for stages a different file with the same content could
// still serve from the cache.
#include <cstdint>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/progress.h"
#include "io/scene.h"
#include "pipeline/artifact_cache.h"
#include "render/camera.h"
#include "render/ray_caster.h"

namespace voxlight::visibility {
class LocalVisibility;
class GlobalVisibility;
class HierarchicalVisibility;
}  // namespace voxlight::visibility

namespace voxlight::pipeline {

enum class StageKind { Input, Precompute, Frame };
std::string toString(StageKind k);

class Run;

struct Stage {
    Stage() = default;
    /// Name, kind and inputs; the functions are set one by one after (a constructor rather than
    /// aggregate initialisation of the first three fields, which -Wextra flags for the rest).
    Stage(std::string name_, StageKind kind_, std::vector<std::string> inputs_)
        : name(std::move(name_)), kind(kind_), inputs(std::move(inputs_)) {}
    std::string name;
    StageKind kind = StageKind::Precompute;
    /// What the key covers, in words (stage names and scene keys), for --explain and the docs.
    std::vector<std::string> inputs;
    /// Non-empty: the stage is not needed for this scene, and this says why.
    std::string skip;
    /// The key of the artifact from the run's earlier keys and the scene; nullopt when an input's
    /// key is not known yet (explain before a volume was ever read).
    std::function<std::optional<std::uint64_t>(const Run&)> key;
    std::function<Artifact(Run&)> compute;
    /// Non-null: the artifact may be kept in a disk cache.
    const Codec* codec = nullptr;
    /// A precompute stage without a codec says why it is not kept on disk (e.g. reading it back
    /// costs more than computing it); shown when a cache directory is set.
    std::string notOnDisk;
    /// Input stages whose product has a content key other than its input key (load_volume: file
    /// identity → content hash). predict: the content key without computing (explain), if known.
    std::function<std::uint64_t(const Run&, const Artifact&)> outputKey;
    std::function<std::optional<std::uint64_t>(const Run&, std::uint64_t)> predictOutputKey;
    /// A short description of the artifact for the stats ("4096 bricks of 16^3").
    std::function<std::string(const Run&, const Artifact&)> describe;
    /// Warnings that belong to the artifact (load_volume: the loader's, e.g. a tilted DICOM
    /// series resampled): every run that uses it reports them, whether it was computed or served
    /// from the cache — a warning about the data does not go quiet because the data was cached.
    std::function<std::vector<std::string>(const Artifact&)> warnings;
    /// Non-null: the stage's artifact is a field an earlier one of the same lineage (the same
    /// volume and settings, another transfer function or cut) may stand in for while it is not
    /// computed yet (RunOptions::staleFields). The key of that lineage, without what changes.
    std::function<std::optional<std::uint64_t>(const Run&)> lineage;
};

/// What a ray-caster method's image stage reads, assembled without rendering: for evaluators of
/// the same optical model outside the pipeline (the viewer's GLSL ray caster), so that they see
/// the same volume, TF tables, options (lights resolved), and fitted camera as the CPU caster.
struct CasterSetup {
    std::string method;
    std::shared_ptr<const core::Volume> volume;
    std::shared_ptr<const optics::TransferFunction> tf;
    render::CasterTables tables;
    render::RenderOptions options;
    std::shared_ptr<const render::Camera> camera;
    /// The SH methods' visibility fields, exactly those their image stage shades from
    /// (render/sh_shading.h); all null for the other methods.
    struct ShFields {
        /// sh-local's field; sh-global's local field (near the light-removing cut faces, and the
        /// viewer's local/global switch). Clip-aware when a plane removes matter for the light.
        std::shared_ptr<const visibility::LocalVisibility> local;
        std::shared_ptr<const visibility::GlobalVisibility> global;              ///< sh-global
        std::shared_ptr<const visibility::HierarchicalVisibility> hierarchical;  ///< ritschel
        /// sh-global: the local field stands in within this distance (mm) of the caster's
        /// render::lightCutFaces (ShGlobalShader); 0 = none.
        float cutBandMm = 0.f;
    } sh;
};

/// The details' "camera" entry: eye, forward, up, right, projection, fov_y_deg, ortho_height_mm.
nlohmann::json cameraDetails(const render::Camera& camera);

struct Plan {
    std::string method;
    /// Set by the methods whose image stage is the CPU ray caster's (not the path tracer's):
    /// what that stage would read, from a run that has run every stage before it.
    std::function<CasterSetup(const Run&)> casterSetup;
    nlohmann::json params = nlohmann::json::object();  ///< method params as used (defaults filled)
    std::vector<Stage> stages;
    std::string imageStage = "render";  ///< the Frame stage whose artifact is the image
};

struct StageRecord {
    std::string name;
    StageKind kind = StageKind::Precompute;
    bool ran = false;      ///< computed in this run (false: cached or not needed)
    std::string reason;    ///< "computed", "cached <key>", "not needed: ..."
    double seconds = 0.0;  ///< Frame stages: the median frame
    std::string key;       ///< 16 hex digits, or "" when unknown / not needed
    std::vector<std::string> inputs;
    /// Size of the stage's artifact (ArtifactCache's accounting; 0 when not needed).
    std::size_t bytes = 0;
    /// The artifact is an earlier field of the stage's lineage, not this scene's
    /// (RunOptions::staleFields; the reason says so too); `wantedKey` is the key of the field
    /// this scene needs (16 hex digits), `key` the stand-in's.
    bool stale = false;
    std::string wantedKey;
};

/// Stats JSON of a record (name, kind, ran, reason, seconds, key, inputs).
nlohmann::json toJson(const StageRecord& r);

/// State of one run that stages read and write.
class Run {
  public:
    Run(const io::Scene& scene, ArtifactCache& cache, const core::Progress& progress)
        : scene_(scene), cache_(cache), progress_(progress) {}
    const io::Scene& scene() const { return scene_; }
    ArtifactCache& cache() const { return cache_; }
    const core::Progress& progress() const { return progress_; }

    /// Output key of an earlier stage (nullopt when unknown or the stage was not needed).
    std::optional<std::uint64_t> keyOf(const std::string& stage) const;
    /// The artifact of an earlier stage (InternalError when it has none: a plan-order bug).
    template <class T>
    std::shared_ptr<const T> get(const std::string& stage) const {
        return artifact(stage).as<T>();
    }
    const Artifact& artifact(const std::string& stage) const;
    bool has(const std::string& stage) const { return artifacts_.count(stage) > 0; }
    /// Method-specific details for the stats (counters, the TF as used, ...). Entries under
    /// "params_resolved" are parameters whose default was resolved while running (the iso mode's
    /// isovalue): they join the params as used.
    nlohmann::json& details() { return details_; }
    const nlohmann::json& details() const { return details_; }
    /// A warning for the user (the CLI prints it on stderr; the stats list it under "warnings"):
    /// what happened, why, and what to do — e.g. an image that shows nothing.
    void warn(const std::string& message) { warnings_.push_back(message); }
    const std::vector<std::string>& warnings() const { return warnings_; }
    /// A further image the method makes beside the main one, by name (pathtrace: "std_error",
    /// the per-pixel standard error of the radiance); the CLI writes it on request.
    void addImage(const std::string& name, std::shared_ptr<const core::ImageRGBA> image) {
        images_[name] = std::move(image);
    }

  private:
    friend class Session;
    const io::Scene& scene_;
    ArtifactCache& cache_;
    const core::Progress& progress_;
    std::map<std::string, std::uint64_t> keys_;
    std::map<std::string, Artifact> artifacts_;
    nlohmann::json details_ = nlohmann::json::object();
    std::vector<std::string> warnings_;
    std::map<std::string, std::shared_ptr<const core::ImageRGBA>> images_;
};

/// Builds a key from named parts; unknown (nullopt) as soon as one upstream key is unknown.
class KeyBuilder {
  public:
    KeyBuilder(const Run& run, const std::string& stage, std::uint32_t version = 1);
    KeyBuilder& stage(const std::string& upstream);
    KeyBuilder& json(const nlohmann::json& value);
    KeyBuilder& text(const std::string& value);
    KeyBuilder& number(double value);
    KeyBuilder& integer(std::uint64_t value);
    std::optional<std::uint64_t> value() const;

  private:
    const Run& run_;
    std::uint64_t h_;
    bool known_ = true;
};

struct RunOptions {
    int frames = 1;  ///< Frame stages run this many times (timing); records report the median
    /// Kronander's interleaved update (an interactive client after a TF change or a cut): a
    /// stage with a lineage (the visibility fields) whose artifact is not in memory uses the last
    /// one computed in its lineage instead, if memory still holds it — old shading over the new
    /// classification at once, while the client computes the new field in a run without this.
    /// Stages downstream key on the stand-in, so no field computed for the old state is ever
    /// stored as the new state's. The records say which stages stood in (StageRecord::stale).
    bool staleFields = false;
    /// Called with each stage's record once the stage is done (ran, cached or not needed), on the
    /// calling thread: the CLI starts loading the image module once the volume is read.
    std::function<void(const StageRecord&)> afterStage = nullptr;
};

/// Most frames one run repeats (a timing aid, not a batch renderer).
inline constexpr int kMaxFrames = 1000;

struct RunResult {
    core::ImageRGBA image;  ///< the image stage's artifact: linear radiance, alpha = coverage
    std::vector<StageRecord> stages;
    std::string imageStage;  ///< the stage whose artifact `image` is
    std::string method;
    nlohmann::json params;              ///< as used
    nlohmann::json details;             ///< method details + "frame_seconds" when frames > 1
    std::vector<std::string> warnings;  ///< Run::warn() messages, each once
    /// Further images by name (Run::addImage): pathtrace's "std_error".
    std::map<std::string, core::ImageRGBA> images;
    /// The record of a stage by name (InternalError when absent).
    const StageRecord& stage(const std::string& name) const;
};

/// Stats JSON (ARCHITECTURE.md §4): stages, total_seconds, peak_rss_mb, method, details.
nlohmann::json statsJson(const RunResult& result, double totalSeconds);

/// Owns the cache; plans and runs scenes. One per process (the CLI) or per viewer; a sweep runs
/// many scenes through one session so they share tables.
class Session {
  public:
    explicit Session(std::size_t memoryBudget = kDefaultMemoryBudget) : cache_(memoryBudget) {}
    ArtifactCache& cache() { return cache_; }

    /// The scene's plan: method from the registry, params parsed strictly, effects checked.
    /// Throws InputError naming the scene key. Loads nothing.
    Plan plan(const io::Scene& scene) const;
    /// What run() would do, stage by stage, without computing anything.
    std::vector<StageRecord> explain(const io::Scene& scene);
    RunResult run(const io::Scene& scene, const RunOptions& options = {},
                  const core::Progress& progress = core::Progress::none());
    /// Runs every stage before the image stage (cached as run() caches them) and returns what
    /// the image stage would read; nullopt when the method does not render with the CPU ray
    /// caster (Plan::casterSetup unset), without running anything. `warnings` receives the
    /// run's warnings when given.
    /// `options.staleFields`: as for run() (an interactive client's interleaved update; the
    /// setup then holds the stand-in fields). `records`: the stages' records when given.
    std::optional<CasterSetup> prepare(const io::Scene& scene,
                                       const core::Progress& progress = core::Progress::none(),
                                       std::vector<std::string>* warnings = nullptr,
                                       const RunOptions& options = {},
                                       std::vector<StageRecord>* records = nullptr);

  private:
    /// Runs the plan's stages in order up to (not including) `stopBefore` ("" = all of them);
    /// returns the seconds of each frame (the Frame stages' sum per frame).
    std::vector<double> runStages(const Plan& plan, Run& run, RunResult& res,
                                  const RunOptions& options, const std::string& stopBefore);
    ArtifactCache cache_;
};

/// A volume loaded outside the pipeline for `scene`'s volume source (loadSceneVolume: the viewer
/// reads it once for its info panel and histogram), handed to `session` as the load_volume
/// stage's artifact under the source's key — so runs of scenes with that source serve it from the
/// memory cache ("cached") instead of reading the file again, and the session holds the same
/// voxels, not a copy. Returns `volume`. The caller vouches that `volume` is what
/// loadSceneVolume(scene) gives (same source, same read options).
std::shared_ptr<const core::Volume> adoptVolume(Session& session, const io::Scene& scene,
                                                std::shared_ptr<const core::Volume> volume);

/// Renders one scene with a fresh session (tests, one-off callers).
RunResult renderScene(const io::Scene& scene, const RunOptions& options = {});

}  // namespace voxlight::pipeline
