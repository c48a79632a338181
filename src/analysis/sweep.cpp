// SPDX-License-Identifier: MIT
#include "analysis/sweep.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>

#include "core/error.h"
#include "core/hash.h"
#include "io/json_field.h"
#include "render/tonemap.h"

namespace voxlight::analysis {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr const char* kEffectsExample = "[\"global_shadows\"]";

/// An array of strings (effects, overrides); `example` shows the right form.
std::vector<std::string> strings(const io::Field& f, const std::string& example) {
    if (!f.isArray())
        f.fail("must be an array of strings, got " + io::typeName(f.raw()) + " " +
                   io::shortDump(f.raw()),
               "write e.g. " + example);
    std::vector<std::string> out;
    for (std::size_t i = 0; i < f.size(); ++i) out.push_back(f.at(i).string());
    return out;
}

/// A non-empty string.
std::string name(const io::Field& f) {
    std::string s = f.string();
    if (s.empty()) f.fail("must not be empty");
    return s;
}

/// A JSON object, as given (method params: the method's own parser checks them).
json object(const io::Field& f) {
    f.expectObject();
    return f.raw();
}

/// A value's text in an id: strings as written, anything else compact JSON (safeId makes it a file
/// name).
std::string valueText(const json& v) { return v.is_string() ? v.get<std::string>() : v.dump(); }

std::string safeId(std::string s) {
    for (char& c : s)
        if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '_'))
            c = '_';
    return s;
}

std::string runField(std::size_t i) { return "runs[" + std::to_string(i) + "]"; }

/// Where reference `index` was written: "reference", or the first run that names it.
std::string referenceField(const SweepSpec& spec, std::size_t index) {
    for (std::size_t i = 0; index > 0 && i < spec.runs.size(); ++i)
        if (spec.runs[i].reference == index) return runField(i) + ".reference";
    return "reference";
}

io::Scene sceneWithMethod(const SweepSpec& spec, const std::string& method, const json& params,
                          const std::optional<std::vector<std::string>>& effects,
                          const std::string& what) {
    json doc = spec.scene;
    doc["method"] = {{"name", method}, {"params", params}};
    if (effects) doc["effects"] = *effects;
    try {
        return io::parseScene(doc, spec.source, spec.sceneDir);
    } catch (const InputError& e) {
        throw InputError(spec.source, what + ": " + e.field(), e.problem(), e.fix());
    }
}

std::string number(double v) {
    if (std::isnan(v)) return "nan";
    if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
    char b[40];
    std::snprintf(b, sizeof b, "%.6g", v);
    return b;
}

std::string csvField(const std::string& s) {
    if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
    std::string q = "\"";
    for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
}

SweepReferenceSpec parseReference(const io::Field& r) {
    r.allowOnly({"method", "params", "effects"});
    SweepReferenceSpec ref;
    if (r.has("method")) {
        ref.method = name(r.child("method"));
        if (ref.method != "pathtrace") ref.params = json::object(), ref.effects.reset();
    }
    if (r.has("params")) ref.params = object(r.child("params"));
    // The path tracer's reference is its reference mode (no denoise, no clamping, to a target
    // error, cached): "reference": false made it an ordinary render, accepted without a word.
    if (ref.method == "pathtrace" && ref.params.contains("reference") &&
        ref.params["reference"] != true)
        r.child("params")
            .child("reference")
            .fail("must be true: the sweep's path-traced reference is the tracer's reference mode",
                  "remove it (a plain path-traced render is a run: {\"method\": \"pathtrace\"})");
    if (r.has("effects")) ref.effects = strings(r.child("effects"), kEffectsExample);
    return ref;
}

}  // namespace

SweepSpec parseSweep(const json& doc, const std::string& source, const fs::path& baseDir) {
    const io::Field top(doc, "", source);
    if (!top.isObject())
        top.fail("a sweep must be a JSON object, got " + io::typeName(doc),
                 "a sweep is {\"scene\": ..., \"runs\": [...]}; see docs/sweeps.md");
    top.allowOnly({"name", "scene", "overrides", "reference", "frames", "runs"});
    SweepSpec spec;
    spec.source = source;
    spec.name = fs::path(source).stem().string();
    if (top.has("name")) spec.name = name(top.child("name"));
    const io::Field scene = top.child("scene");
    if (scene.isString()) {
        fs::path p = scene.string();
        if (p.is_relative()) p = baseDir / p;
        try {
            spec.scene = io::readJsonFile(p);
        } catch (const InputError& e) {
            scene.fail(e.what());
        }
        spec.sceneDir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
    } else if (scene.isObject()) {
        spec.scene = scene.raw();
        spec.sceneDir = baseDir;
    } else {
        scene.fail(top.has("scene") ? "must be a scene file name or an inline scene object, got " +
                                          io::typeName(scene.raw())
                                    : "is missing",
                   "give a scene file (relative to the sweep) or an inline scene object");
    }
    std::vector<io::OverrideRecord> records;
    if (top.has("overrides")) {
        const io::Field o = top.child("overrides");
        const std::vector<std::string> assignments = strings(o, "[\"image.width=96\"]");
        try {
            records = io::applyOverrides(spec.scene, assignments);
        } catch (const InputError& e) {
            o.fail(e.what());
        }
    }
    // The scene's own method and effects give way to each run's.
    spec.scene.erase("method");
    // The scene alone (each run adds its method): its own errors are the scene's or an
    // override's, not the first reference's or run's that happens to be parsed first.
    // A volume file that is not there is found here too, before any folder is made (the read
    // would name the path alone).
    const auto blame = [&](const std::string& field) {
        if (const io::OverrideRecord* r = io::blamedOverride(records, field)) {
            const std::string said = r->said;  // "--set key=value": the sweep says it without
            return "overrides: " + (said.rfind("--set ", 0) == 0 ? said.substr(6) : said);
        }
        return std::string("scene");
    };
    try {
        json alone = spec.scene;
        alone.erase("effects");
        const io::VolumeSource v = io::parseScene(alone, source, spec.sceneDir).volume;
        std::error_code ec;
        if (v.phantom.empty() && !fs::exists(v.path, ec)) {
            const bool overridden = io::blamedOverride(records, "volume.path") != nullptr;
            const std::string base = spec.sceneDir.empty() ? "." : spec.sceneDir.string();
            throw InputError(source, "volume",
                             "names '" + v.path.string() + "', which does not exist",
                             "fix the path; a relative one is read from " +
                                 (overridden ? std::string("the current directory") : base));
        }
    } catch (const InputError& e) {
        throw InputError(source, blame(e.field()) + ": " + e.field(), e.problem(), e.fix());
    }
    if (top.has("reference")) spec.references[0] = parseReference(top.child("reference"));
    top.get("frames", spec.frames, 1, kMaxSweepFrames);
    const io::Field runs = top.child("runs");
    if (!runs.isArray() || runs.size() == 0)
        runs.fail("must be a non-empty array of runs",
                  "e.g. [{\"method\": \"gradient\"}, {\"method\": \"sh-local\", \"axes\": "
                  "{\"rays\": [16, 64]}}]");
    std::set<std::string> labels;
    for (std::size_t i = 0; i < runs.size(); ++i) {
        const io::Field r = runs.at(i);
        r.allowOnly({"method", "label", "params", "effects", "axes", "combine", "reference"});
        SweepRun run;
        run.method = name(r.child("method"));
        run.label = r.has("label") ? name(r.child("label")) : run.method;
        if (run.label.find(',') != std::string::npos)
            r.child("label").fail("'" + run.label + "' holds a comma, where --only splits its list",
                                  "write the label without commas");
        if (!labels.insert(run.label).second)
            r.child("label").fail("'" + run.label + "' is used twice",
                                  "give each run of the same method its own \"label\"");
        if (r.has("params")) run.params = object(r.child("params"));
        if (r.has("effects")) run.effects = strings(r.child("effects"), kEffectsExample);
        if (r.has("axes")) {
            const io::Field axes = r.child("axes");
            axes.expectObject();
            // nlohmann's object keeps keys sorted; the order of the axes is that order.
            for (const auto& [key, values] : axes.raw().items()) {
                if (!values.is_array() || values.empty())
                    axes.child(key).fail("must be a non-empty array of values",
                                         "e.g. [16, 64, 256]");
                // A value given twice rendered and measured twice, two rows of one variant.
                for (std::size_t i = 0; i < values.size(); ++i)
                    for (std::size_t j = 0; j < i; ++j)
                        if (values[i] == values[j])
                            axes.child(key).at(i).fail(values[i].dump() + " is already " + key +
                                                           "[" + std::to_string(j) + "]",
                                                       "give each value once");
                run.axes.emplace_back(key, std::vector<json>(values.begin(), values.end()));
            }
        }
        std::string combine = "one-at-a-time";
        r.get("combine", combine, {"one-at-a-time", "grid"});
        run.grid = combine == "grid";
        if (r.has("reference")) {
            const SweepReferenceSpec ref = parseReference(r.child("reference"));
            const auto same = std::find(spec.references.begin(), spec.references.end(), ref);
            run.reference = std::size_t(same - spec.references.begin());
            if (same == spec.references.end()) spec.references.push_back(ref);
        }
        spec.runs.push_back(std::move(run));
    }
    // The number of variants, before anything is expanded: a grid multiplies.
    std::size_t total = 0;
    for (const SweepRun& run : spec.runs) {
        std::size_t n = 1;
        if (run.grid) {
            for (const auto& a : run.axes) n = std::min(n * a.second.size(), kMaxSweepVariants + 1);
        } else {
            for (const auto& a : run.axes) n += a.second.size();
        }
        total += n;
        if (total > kMaxSweepVariants)
            throw InputError(
                source, "runs",
                "expand to more than " + std::to_string(kMaxSweepVariants) + " variants",
                "use fewer values or \"combine\": \"one-at-a-time\"");
    }
    return spec;
}

SweepSpec loadSweep(const fs::path& path) {
    const json doc = io::readJsonFile(path);
    fs::path base = path.parent_path();
    if (base.empty()) base = ".";
    return parseSweep(doc, path.string(), base);
}

std::vector<SweepItem> expandSweep(const SweepSpec& spec) {
    std::vector<SweepItem> items;
    std::set<std::string> ids;
    auto add = [&](const SweepRun& run, const std::string& axis, const json& value,
                   const json& params, std::string id) {
        id = safeId(id);
        // Ids stay unique even when two values print alike ("1" and "1.0" both give "1").
        std::string unique = id;
        for (int k = 2; !ids.insert(unique).second; ++k) unique = id + "-" + std::to_string(k);
        SweepItem it;
        it.index = items.size();
        it.id = unique;
        it.label = run.label;
        it.method = run.method;
        it.axis = axis;
        it.value = value;
        it.params = params;
        it.effects = run.effects;
        it.reference = run.reference;
        items.push_back(std::move(it));
    };
    for (const SweepRun& run : spec.runs) {
        if (run.axes.empty()) {
            add(run, "", nullptr, run.params, run.label);
        } else if (run.grid) {
            std::vector<std::size_t> at(run.axes.size(), 0);
            for (std::size_t n = 0;; ++n) {
                json params = run.params;
                for (std::size_t a = 0; a < run.axes.size(); ++a)
                    params[run.axes[a].first] = run.axes[a].second[at[a]];
                char b[16];
                std::snprintf(b, sizeof b, "%03zu", n);
                add(run, "", nullptr, params, run.label + "-grid-" + b);
                std::size_t a = 0;
                for (; a < run.axes.size(); ++a) {
                    if (++at[a] < run.axes[a].second.size()) break;
                    at[a] = 0;
                }
                if (a == run.axes.size()) break;
            }
        } else {
            add(run, "", nullptr, run.params, run.label + "-base");
            for (const auto& [name, values] : run.axes)
                for (const json& v : values) {
                    json params = run.params;
                    params[name] = v;
                    add(run, name, v, params, run.label + "-" + name + "-" + valueText(v));
                }
        }
    }
    return items;
}

namespace {
/// Where a variant comes from, for messages: "runs[1].axes.rays=64", or "runs[1] (ID)" for a
/// run's base or a grid point.
std::string itemWhere(const SweepSpec& spec, const SweepItem& item) {
    std::size_t run = 0;
    for (; run < spec.runs.size() && spec.runs[run].label != item.label; ++run) {
    }
    if (!item.axis.empty()) return runField(run) + ".axes." + item.axis + "=" + item.value.dump();
    return runField(run) + " (" + item.id + ")";
}
}  // namespace

io::Scene variantScene(const SweepSpec& spec, const SweepItem& item) {
    return sceneWithMethod(spec, item.method, item.params, item.effects, itemWhere(spec, item));
}

io::Scene referenceScene(const SweepSpec& spec, std::size_t index) {
    const SweepReferenceSpec& r = spec.references.at(index);
    return sceneWithMethod(spec, r.method, r.params, r.effects, referenceField(spec, index));
}

void validateSweep(const SweepSpec& spec, const std::vector<SweepItem>& items,
                   const pipeline::Session& session) {
    auto check = [&](const io::Scene& s, const std::string& what) {
        try {
            (void)session.plan(s);
        } catch (const InputError& e) {
            throw InputError(spec.source, what + ": " + e.field(), e.problem(), e.fix());
        }
    };
    for (std::size_t i = 0; i < spec.references.size(); ++i)
        check(referenceScene(spec, i), referenceField(spec, i));
    for (const SweepItem& it : items) check(variantScene(spec, it), itemWhere(spec, it));
}

SweepRunner::SweepRunner(const SweepSpec& spec, pipeline::Session& variants,
                         pipeline::Session& references)
    : spec_(spec), variants_(variants), references_(references) {}

namespace {
core::ImageRGBA displayOf(const core::ImageRGBA& linear, const io::Scene& s) {
    return render::toDisplay(linear, float(s.image.exposureStops),
                             render::displayFromString(s.image.display));
}
}  // namespace

const SweepReference& SweepRunner::reference(std::size_t index, const core::Progress& progress) {
    if (const auto it = references_done_.find(index); it != references_done_.end())
        return it->second;
    const io::Scene s = referenceScene(spec_, index);
    pipeline::RunOptions options;
    options.afterStage = afterStage_;
    pipeline::RunResult r = references_.run(s, options, progress);
    SweepReference ref;
    ref.linear = std::move(r.image);
    ref.display = displayOf(ref.linear, s);
    const json& pt = r.details.contains("pathtrace") ? r.details["pathtrace"] : json::object();
    // Null (one sample per pixel: unknown) or absent (a reference cached before 7 December has
    // no expected_nrmse): nan, not a floor in other units.
    const auto number = [&](const char* key) {
        return pt.contains(key) && pt[key].is_number() ? pt[key].get<double>()
                                                       : std::numeric_limits<double>::quiet_NaN();
    };
    ref.relativeStdError = number("relative_std_error");
    ref.expectedNrmse = number("expected_nrmse");
    ref.spp = pt.value("spp", 0LL);
    ref.warnings = r.warnings;
    for (const auto& st : r.stages)
        if (st.ran && st.kind != pipeline::StageKind::Input) ref.seconds += st.seconds;
    // Served from the cache: the reference stage (params "reference": true) did not run.
    for (const auto& st : r.stages)
        if (st.name == "reference") ref.cached = !st.ran;
    return references_done_.emplace(index, std::move(ref)).first->second;
}

SweepRow SweepRunner::run(const SweepItem& item, const core::Progress& progress,
                          SweepImages* images) {
    const SweepReference& ref = reference(item.reference, progress);
    const io::Scene s = variantScene(spec_, item);
    pipeline::RunOptions options;
    options.frames = item.method == "pathtrace" ? 1 : spec_.frames;
    options.afterStage = afterStage_;
    pipeline::RunResult r = variants_.run(s, options, progress);
    SweepRow row;
    row.item = item;
    row.warnings = r.warnings;
    row.referenceError = ref.expectedNrmse;
    std::size_t bytes = 0;
    for (const auto& st : r.stages) {
        if (st.kind != pipeline::StageKind::Precompute || st.key.empty()) continue;
        const std::string k = st.name + ":" + st.key;
        if (st.ran) cost_[k] = st.seconds;
        const auto it = cost_.find(k);
        // Not computed in this process (a disk cache): what it took here is all that is known.
        row.precomputeSeconds += it != cost_.end() ? it->second : st.seconds;
        bytes += st.bytes;
    }
    row.frameSeconds = r.stage(r.imageStage).seconds;
    row.memoryMb = double(bytes) / (1024.0 * 1024.0);
    if (r.image.width != ref.linear.width || r.image.height != ref.linear.height)
        throw InputError(spec_.source, item.id,
                         "renders " + std::to_string(r.image.width) + "x" +
                             std::to_string(r.image.height) + " but the reference is " +
                             std::to_string(ref.linear.width) + "x" +
                             std::to_string(ref.linear.height),
                         "leave image size to the scene, not to method params");
    MetricOptions linear{Encoding::Linear, coverageMask(ref.linear, r.image)};
    bool covered = false;
    for (auto m : linear.mask) covered = covered || m;
    if (!covered) linear.mask.clear();  // neither covers a pixel: every pixel (all empty)
    row.nrmse = errorStats(ref.linear, r.image, linear).nrmse;
    const core::ImageRGBA display = displayOf(r.image, s);
    MetricOptions disp{Encoding::Display, linear.mask};
    const ErrorStats e = errorStats(ref.display, display, disp, 1.0);
    row.rmse255 = 255.0 * e.rmse;
    row.psnrDb = e.psnrDb;
    row.ssim = ssim(ref.display, display, disp).mean;
    FlipResult f = flip(ref.display, display, disp);
    row.flip = f.mean;
    row.detected = detectionFraction(f.map, disp, {kSweepDetectionThreshold});
    if (images) {
        images->display = display;
        images->errorMap = errorMap(f.map, {kSweepMapMax});
    }
    return row;
}

std::string sweepCsvHeader() {
    return "index,id,label,method,axis,value,params,precompute_s,frame_s,memory_mb,nrmse,rmse_255,"
           "psnr_db,ssim,flip,detected,reference_error,reference";
}

std::string sweepCsvRow(const SweepRow& row) {
    const SweepItem& it = row.item;
    std::string value = it.value.is_null()     ? ""
                        : it.value.is_string() ? it.value.get<std::string>()
                                               : it.value.dump();
    std::string s = std::to_string(it.index) + "," + csvField(it.id) + "," + csvField(it.label) +
                    "," + csvField(it.method) + "," + csvField(it.axis) + "," + csvField(value) +
                    "," + csvField(it.params.dump());
    for (double v : {row.precomputeSeconds, row.frameSeconds, row.memoryMb, row.nrmse, row.rmse255,
                     row.psnrDb, row.ssim, row.flip, row.detected, row.referenceError})
        s += "," + number(v);
    return s + "," + std::to_string(it.reference);
}

}  // namespace voxlight::analysis
