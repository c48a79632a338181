// SPDX-License-Identifier: MIT
#include "pipeline/pipeline.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/hash.h"
#include "core/timing.h"
#include "pipeline/registry.h"
#include "render/tonemap.h"

namespace voxlight::pipeline {

using nlohmann::json;

std::string toString(StageKind k) {
    switch (k) {
        case StageKind::Input:
            return "input";
        case StageKind::Precompute:
            return "precompute";
        case StageKind::Frame:
            return "frame";
    }
    return "?";
}

json toJson(const StageRecord& r) {
    json j = {{"name", r.name},     {"kind", toString(r.kind)}, {"ran", r.ran},
              {"reason", r.reason}, {"seconds", r.seconds},     {"key", r.key},
              {"inputs", r.inputs}};
    if (r.stale) j["stale"] = true, j["wanted_key"] = r.wantedKey;
    return j;
}

std::optional<std::uint64_t> Run::keyOf(const std::string& stage) const {
    const auto it = keys_.find(stage);
    if (it == keys_.end()) return std::nullopt;
    return it->second;
}

const Artifact& Run::artifact(const std::string& stage) const {
    const auto it = artifacts_.find(stage);
    if (it == artifacts_.end())
        throw InternalError("stage '" + stage + "' has no artifact yet (plan order)");
    return it->second;
}

KeyBuilder::KeyBuilder(const Run& run, const std::string& stage, std::uint32_t version)
    : run_(run), h_(core::Hasher().add(stage).add(version).value()) {}

KeyBuilder& KeyBuilder::stage(const std::string& upstream) {
    const auto k = run_.keyOf(upstream);
    if (!k) known_ = false;
    h_ = core::Hasher(h_).add(upstream).add(k.value_or(0)).value();
    return *this;
}

KeyBuilder& KeyBuilder::json(const nlohmann::json& value) {
    // dump() of nlohmann's default (sorted) object map is canonical.
    h_ = core::Hasher(h_).add(value.dump()).value();
    return *this;
}

KeyBuilder& KeyBuilder::text(const std::string& value) {
    h_ = core::Hasher(h_).add(value).value();
    return *this;
}

KeyBuilder& KeyBuilder::number(double value) {
    h_ = core::Hasher(h_).add(value).value();
    return *this;
}

KeyBuilder& KeyBuilder::integer(std::uint64_t value) {
    h_ = core::Hasher(h_).add(value).value();
    return *this;
}

std::optional<std::uint64_t> KeyBuilder::value() const {
    if (!known_) return std::nullopt;
    return h_;
}

const StageRecord& RunResult::stage(const std::string& name) const {
    for (const auto& s : stages)
        if (s.name == name) return s;
    throw InternalError("no stage '" + name + "' in this run");
}

json statsJson(const RunResult& r, double totalSeconds) {
    json stages = json::array();
    for (const auto& s : r.stages) stages.push_back(toJson(s));
    json j = {{"stages", stages},
              {"total_seconds", totalSeconds},
              {"peak_rss_mb", core::peakRssMiB()},
              {"method", {{"name", r.method}, {"params", r.params}}}};
    for (auto it = r.details.begin(); it != r.details.end(); ++it) j[it.key()] = it.value();
    return j;
}

Plan Session::plan(const io::Scene& scene) const {
    const MethodRegistry& reg = MethodRegistry::instance();
    const MethodInfo* m = reg.find(scene.method.name);
    if (!m) {
        throw InputError(scene.source, "method.name",
                         "'" + scene.method.name + "' is not a method of this build",
                         "choose one of: " + joinNames(reg.names()));
    }
    // Effects: known names, and ones this method simulates.
    for (std::size_t i = 0; i < scene.effects.size(); ++i) {
        const std::string& e = scene.effects[i];
        const std::string field = "effects[" + std::to_string(i) + "]";
        const auto& cat = effectCatalog();
        if (std::none_of(cat.begin(), cat.end(),
                         [&](const EffectInfo& c) { return c.name == e; })) {
            std::vector<std::string> names;
            for (const auto& c : cat) names.push_back(c.name);
            throw InputError(scene.source, field, "'" + e + "' is not an effect",
                             "choose from: " + joinNames(names));
        }
        if (std::find(m->effects.begin(), m->effects.end(), e) == m->effects.end()) {
            std::vector<std::string> names;
            for (const auto& other : reg.methods())
                if (std::find(other.effects.begin(), other.effects.end(), e) != other.effects.end())
                    names.push_back(other.name);
            const std::string providers = joinNames(names);
            throw InputError(
                scene.source, field, "method '" + m->name + "' does not simulate '" + e + "'",
                providers.empty() ? "no method of this build simulates it yet; remove it"
                                  : "use " + providers + ", or remove it");
        }
    }
    // Shadows are what the visibility methods compute, not a stage they can leave out: a list
    // that asks for fewer was accepted and ignored (sh-global with ["local_shadows"] still cast
    // shadows from across the volume). The path tracer's and PVRT's shadows are whole; their
    // lists choose multiple scattering ([] and ["global_shadows"]: single scattering).
    if (scene.effectsGiven) {
        const bool local = wantsEffect(scene, "local_shadows"),
                   global = wantsEffect(scene, "global_shadows");
        const std::string& n = m->name;
        if (n == "sh-local" && !local)
            throw InputError(scene.source, "effects",
                             "method 'sh-local' simulates local_shadows, which this list leaves "
                             "out",
                             "add \"local_shadows\", or use gradient for shading without shadows");
        if ((n == "sh-global" || n == "ritschel") && !global)
            throw InputError(scene.source, "effects",
                             "method '" + n +
                                 "' always simulates global_shadows (its visibility reaches the "
                                 "volume's boundary), which this list leaves out",
                             local ? "use sh-local for local shadows only, or add "
                                     "\"global_shadows\""
                                   : "add \"global_shadows\", or use gradient for shading "
                                     "without shadows");
        if ((n == "pathtrace" || n == "pvrt") && local && !global)
            throw InputError(scene.source, "effects",
                             "method '" + n +
                                 "' casts every shadow: local_shadows cannot be had without "
                                 "global_shadows",
                             "add \"global_shadows\", or leave both out");
    }
    ParamReader reader(scene, m->params);
    Plan p = m->plan(scene, reader);
    p.method = m->name;
    return p;
}

namespace {
double median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

/// The key a stage that is not needed passes downstream (a fixed value: "not needed" is an input
/// like any other, and known before running).
constexpr std::uint64_t kNotNeededKey = 0x6e6f742d6e656564ull;  // "not-need"

std::string cachedReason(std::uint64_t key, bool disk) {
    return "cached " + core::hexKey(key).substr(0, 8) + (disk ? " (disk)" : "");
}
}  // namespace

std::vector<StageRecord> Session::explain(const io::Scene& scene) {
    const Plan plan = this->plan(scene);
    Run run(scene, cache_, core::Progress::none());
    std::vector<StageRecord> out;
    for (const Stage& st : plan.stages) {
        StageRecord r;
        r.name = st.name;
        r.kind = st.kind;
        r.inputs = st.inputs;
        if (!st.skip.empty()) {
            r.reason = st.skip;
            run.keys_[st.name] = kNotNeededKey;
            out.push_back(r);
            continue;
        }
        const std::optional<std::uint64_t> key = st.key(run);
        if (!key) {
            r.ran = true;
            r.reason = "computed (volume not read before)";
            out.push_back(r);
            continue;
        }
        r.key = core::hexKey(*key);
        const bool memory = st.kind != StageKind::Frame && cache_.inMemory(st.name, *key);
        const bool disk = !memory && st.kind == StageKind::Precompute && st.codec &&
                          cache_.onDisk(st.name, *key, *st.codec);
        if (memory || disk) {
            r.reason = cachedReason(*key, disk);
        } else {
            r.ran = true;
            r.reason = "computed";
            if (cache_.directory() && st.kind == StageKind::Precompute && !st.notOnDisk.empty())
                r.reason += " (not kept on disk: " + st.notOnDisk + ")";
        }
        std::optional<std::uint64_t> out_key = key;
        if (st.predictOutputKey) out_key = st.predictOutputKey(run, *key);
        if (out_key) run.keys_[st.name] = *out_key;
        out.push_back(r);
    }
    return out;
}

namespace {

/// Coverage from which a pixel shows the volume (under one 8-bit level below it shows nothing, as
/// the ray caster's empty-image check says).
constexpr float kShownAlpha = 0.5f / 255.f;
/// Share of the pixels showing the volume that may be white before the image is called washed
/// out. A flat plate under a point light is white over 40 % of what shows and reads well
/// (datasets/scenes/kronander.json); a T1 head under an HDR environment at intensity 1 is white
/// over 88 %, every fold lost — said nowhere until 7 December.
constexpr double kWashedOutFraction = 0.5;

/// "the image is washed out: …" when the display turns most of what shows white; empty otherwise.
/// MIP and MinIP show the window's ramp, white on purpose where the data pass the window.
std::string washedOutWarning(const std::string& method, const core::ImageRGBA& film,
                             const io::Scene& scene) {
    if (method == "mip" || method == "minip") return {};
    const render::DisplayClipping c =
        render::displayClipping(film, float(scene.image.exposureStops),
                                render::displayFromString(scene.image.display), kShownAlpha);
    if (c.shown == 0 || double(c.white) <= kWashedOutFraction * double(c.shown)) return {};
    std::ostringstream os;
    os << "the image is washed out: " << std::lround(100.0 * double(c.white) / double(c.shown))
       << " % of the pixels that show the volume are white on the '" << scene.image.display
       << "' display, their detail lost (set image.exposure to " << c.exposureToFit
       << ", lower the lights' intensity";
    if (scene.image.display != "filmic") os << ", or set image.display to \"filmic\"";
    os << ")";
    return os.str();
}

}  // namespace

RunResult Session::run(const io::Scene& scene, const RunOptions& options,
                       const core::Progress& progress) {
    if (options.frames < 1 || options.frames > kMaxFrames)
        throw InputError("command line", "--frames",
                         "must be between 1 and " + std::to_string(kMaxFrames));
    const Plan plan = this->plan(scene);
    Run run(scene, cache_, progress);
    RunResult res;
    res.method = plan.method;
    res.params = plan.params;
    const std::vector<double> frameSeconds = runStages(plan, run, res, options, "");
    if (!run.has(plan.imageStage))
        throw InternalError("plan of '" + plan.method + "' has no image stage '" + plan.imageStage +
                            "'");
    res.image = *run.get<core::ImageRGBA>(plan.imageStage);
    res.imageStage = plan.imageStage;
    for (const auto& [name, image] : run.images_) res.images[name] = *image;
    res.details = run.details();
    const auto denoised = res.images.find("denoised");
    if (const std::string w = washedOutWarning(
            plan.method, denoised != res.images.end() ? denoised->second : res.image, scene);
        !w.empty())
        run.warn(w);
    for (const auto& w : run.warnings())  // a Frame stage may warn once per frame
        if (std::find(res.warnings.begin(), res.warnings.end(), w) == res.warnings.end())
            res.warnings.push_back(w);
    if (!res.warnings.empty()) res.details["warnings"] = res.warnings;
    if (res.details.contains("params_resolved")) {
        for (auto it = res.details["params_resolved"].begin();
             it != res.details["params_resolved"].end(); ++it)
            res.params[it.key()] = it.value();
        res.details.erase("params_resolved");
    }
    if (options.frames > 1) res.details["frame_seconds"] = frameSeconds;
    return res;
}

std::optional<CasterSetup> Session::prepare(const io::Scene& scene, const core::Progress& progress,
                                            std::vector<std::string>* warnings,
                                            const RunOptions& options,
                                            std::vector<StageRecord>* records) {
    const Plan plan = this->plan(scene);
    if (!plan.casterSetup) return std::nullopt;
    Run run(scene, cache_, progress);
    RunResult res;
    runStages(plan, run, res, options, plan.imageStage);
    if (warnings) *warnings = run.warnings();
    if (records) *records = res.stages;
    CasterSetup setup = plan.casterSetup(run);
    setup.method = plan.method;
    return setup;
}

std::vector<double> Session::runStages(const Plan& plan, Run& run, RunResult& res,
                                       const RunOptions& options, const std::string& stopBefore) {
    std::vector<double> frameSeconds(std::size_t(options.frames), 0.0);
    for (const Stage& st : plan.stages) {
        if (st.name == stopBefore) break;
        StageRecord r;
        r.name = st.name;
        r.kind = st.kind;
        r.inputs = st.inputs;
        if (!st.skip.empty()) {
            r.reason = st.skip;
            run.keys_[st.name] = kNotNeededKey;
            res.stages.push_back(r);
            if (options.afterStage) options.afterStage(r);
            continue;
        }
        const std::optional<std::uint64_t> keyOpt = st.key(run);
        if (!keyOpt) throw InternalError("stage '" + st.name + "' has an unknown input key");
        std::uint64_t key = *keyOpt;
        // The stage's lineage and, with staleFields, the last field of it standing in.
        const std::optional<std::uint64_t> lineage =
            st.lineage && st.kind == StageKind::Precompute ? st.lineage(run) : std::nullopt;
        const std::string lastRecord = "last_of_lineage:" + st.name;
        if (options.staleFields && lineage && !cache_.inMemory(st.name, key))
            if (const auto last = cache_.record(lastRecord, *lineage);
                last && *last != key && cache_.inMemory(st.name, *last)) {
                r.wantedKey = core::hexKey(key);
                key = *last;
                r.stale = true;
            }
        r.key = core::hexKey(key);
        Artifact a;
        if (st.kind == StageKind::Frame) {
            // Every frame, never cached: the median frame is the stage's time.
            std::vector<double> times;
            for (int f = 0; f < options.frames; ++f) {
                core::Stopwatch sw;
                a = st.compute(run);
                times.push_back(sw.seconds());
                frameSeconds[std::size_t(f)] += times.back();
            }
            r.seconds = median(times);
            r.ran = true;
            r.reason = "computed";
        } else {
            core::Stopwatch sw;
            bool disk = false;
            if (auto m = cache_.findInMemory(st.name, key)) {
                a = *m;
            } else if (st.kind == StageKind::Precompute && st.codec) {
                if (auto d = cache_.readDisk(st.name, key, *st.codec)) {
                    a = *d;
                    disk = true;
                    cache_.putInMemory(st.name, key, a);
                }
            }
            if (!a.empty()) {
                r.reason = r.stale ? "stale: the last field computed for an earlier state (" +
                                         core::hexKey(key).substr(0, 8) +
                                         ") stands in while this one is computed"
                                   : cachedReason(key, disk);
            } else {
                a = st.compute(run);
                r.ran = true;
                r.reason = "computed";
                if (cache_.directory() && !st.notOnDisk.empty())
                    r.reason += " (not kept on disk: " + st.notOnDisk + ")";
                cache_.putInMemory(st.name, key, a);
                if (st.kind == StageKind::Precompute && st.codec)
                    cache_.writeDisk(st.name, key, *st.codec, a);
            }
            r.seconds = sw.seconds();
            if (lineage && !r.stale) cache_.putRecord(lastRecord, *lineage, key, false);
        }
        if (st.describe) r.reason += ": " + st.describe(run, a);
        if (st.warnings)
            for (const auto& w : st.warnings(a)) run.warn(w);
        run.keys_[st.name] = st.outputKey ? st.outputKey(run, a) : key;
        r.bytes = a.bytes;
        run.artifacts_[st.name] = a;
        res.stages.push_back(r);
        if (options.afterStage) options.afterStage(r);
    }
    return frameSeconds;
}

nlohmann::json cameraDetails(const render::Camera& cam) {
    return {{"eye", {cam.eye().x, cam.eye().y, cam.eye().z}},
            {"forward", {cam.forward().x, cam.forward().y, cam.forward().z}},
            {"up", {cam.up().x, cam.up().y, cam.up().z}},
            {"right", {cam.right().x, cam.right().y, cam.right().z}},
            {"projection",
             cam.projection() == render::Projection::Perspective ? "perspective" : "orthographic"},
            {"fov_y_deg", cam.fovY() * 180.0 / 3.14159265358979323846},
            {"ortho_height_mm", cam.orthoHeight()}};
}

RunResult renderScene(const io::Scene& scene, const RunOptions& options) {
    Session session;
    return session.run(scene, options);
}

}  // namespace voxlight::pipeline
