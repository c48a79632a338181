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
#include "render/tonemap.h"

namespace voxlight::analysis {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::string typeName(const json& v) { return v.type_name(); }

/// Checks that `doc` holds only `allowed` keys (a typo is an error, not a silently ignored key).
void checkKeys(const json& doc, const std::set<std::string>& allowed, const std::string& source,
               const std::string& where) {
    for (const auto& [k, v] : doc.items()) {
        (void)v;
        if (!allowed.count(k))
            throw InputError(source, where.empty() ? k : where + "." + k, "is not a known key",
                             "use one of: " + joinNames(std::vector<std::string>(allowed.begin(),
                                                                                 allowed.end())));
    }
}

std::vector<std::string> stringList(const json& v, const std::string& source,
                                    const std::string& field) {
    if (!v.is_array())
        throw InputError(source, field, "is " + typeName(v) + ", not an array of strings",
                         "write e.g. [\"global_shadows\"]");
    std::vector<std::string> out;
    for (std::size_t i = 0; i < v.size(); ++i) {
        if (!v[i].is_string())
            throw InputError(source, field + "[" + std::to_string(i) + "]",
                             "is " + typeName(v[i]) + ", not a string");
        out.push_back(v[i].get<std::string>());
    }
    return out;
}

/// A value's text in an id: numbers and strings as written, anything else compact JSON.
std::string valueText(const json& v) {
    std::string s = v.is_string() ? v.get<std::string>() : v.dump();
    for (char& c : s)
        if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '_'))
            c = '_';
    return s;
}

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

SweepReferenceSpec parseReference(const json& r, const std::string& source,
                                  const std::string& field) {
    if (!r.is_object())
        throw InputError(source, field, "is " + typeName(r) + ", not an object",
                         "write {\"method\": ..., \"params\": {...}, \"effects\": [...]}");
    checkKeys(r, {"method", "params", "effects"}, source, field);
    SweepReferenceSpec ref;
    if (r.contains("method")) {
        if (!r["method"].is_string())
            throw InputError(source, field + ".method", "is not a string");
        ref.method = r["method"].get<std::string>();
        if (ref.method != "pathtrace") ref.params = json::object(), ref.effects.reset();
    }
    if (r.contains("params")) {
        if (!r["params"].is_object())
            throw InputError(source, field + ".params", "is not an object");
        ref.params = r["params"];
    }
    if (r.contains("effects")) ref.effects = stringList(r["effects"], source, field + ".effects");
    return ref;
}

}  // namespace

SweepSpec parseSweep(const json& doc, const std::string& source, const fs::path& baseDir) {
    if (!doc.is_object())
        throw InputError(source, "(top level)", "is " + typeName(doc) + ", not an object",
                         "a sweep is {\"scene\": ..., \"runs\": [...]}; see docs/sweeps.md");
    checkKeys(doc, {"name", "scene", "overrides", "reference", "frames", "runs"}, source, "");
    SweepSpec spec;
    spec.source = source;
    spec.name = fs::path(source).stem().string();
    if (doc.contains("name")) {
        if (!doc["name"].is_string() || doc["name"].get<std::string>().empty())
            throw InputError(source, "name", "must be a non-empty string");
        spec.name = doc["name"].get<std::string>();
    }
    if (!doc.contains("scene"))
        throw InputError(source, "scene", "is missing",
                         "give a scene file (relative to the sweep) or an inline scene object");
    const json& scene = doc["scene"];
    if (scene.is_string()) {
        fs::path p = scene.get<std::string>();
        if (p.is_relative()) p = baseDir / p;
        try {
            spec.scene = io::readJsonFile(p);
        } catch (const InputError& e) {
            throw InputError(source, "scene", e.what());
        }
        spec.sceneDir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
    } else if (scene.is_object()) {
        spec.scene = scene;
        spec.sceneDir = baseDir;
    } else {
        throw InputError(source, "scene", "is " + typeName(scene) + ", not a file name or object");
    }
    if (doc.contains("overrides")) {
        const std::vector<std::string> o = stringList(doc["overrides"], source, "overrides");
        try {
            io::applyOverrides(spec.scene, o);
        } catch (const InputError& e) {
            throw InputError(source, "overrides", e.what());
        }
    }
    // The scene's own method and effects give way to each run's.
    spec.scene.erase("method");
    if (doc.contains("reference"))
        spec.references[0] = parseReference(doc["reference"], source, "reference");
    if (doc.contains("frames")) {
        const json& f = doc["frames"];
        if (!f.is_number_integer() || f.get<long long>() < 1 ||
            f.get<long long>() > kMaxSweepFrames)
            throw InputError(source, "frames",
                             "must be an integer in 1.." + std::to_string(kMaxSweepFrames));
        spec.frames = f.get<int>();
    }
    if (!doc.contains("runs") || !doc["runs"].is_array() || doc["runs"].empty())
        throw InputError(source, "runs", "must be a non-empty array of runs",
                         "e.g. [{\"method\": \"gradient\"}, {\"method\": \"sh-local\", \"axes\": "
                         "{\"rays\": [16, 64]}}]");
    std::set<std::string> labels;
    for (std::size_t i = 0; i < doc["runs"].size(); ++i) {
        const json& r = doc["runs"][i];
        const std::string where = runField(i);
        if (!r.is_object())
            throw InputError(source, where, "is " + typeName(r) + ", not an object");
        checkKeys(r, {"method", "label", "params", "effects", "axes", "combine", "reference"},
                  source, where);
        SweepRun run;
        if (!r.contains("method") || !r["method"].is_string())
            throw InputError(source, where + ".method", "must be a method name (string)");
        run.method = r["method"].get<std::string>();
        run.label = run.method;
        if (r.contains("label")) {
            if (!r["label"].is_string() || r["label"].get<std::string>().empty())
                throw InputError(source, where + ".label", "must be a non-empty string");
            run.label = r["label"].get<std::string>();
        }
        if (!labels.insert(run.label).second)
            throw InputError(source, where + ".label", "'" + run.label + "' is used twice",
                             "give each run of the same method its own \"label\"");
        if (r.contains("params")) {
            if (!r["params"].is_object())
                throw InputError(source, where + ".params",
                                 "is " + typeName(r["params"]) + ", not an object");
            run.params = r["params"];
        }
        if (r.contains("effects"))
            run.effects = stringList(r["effects"], source, where + ".effects");
        if (r.contains("axes")) {
            const json& axes = r["axes"];
            if (!axes.is_object())
                throw InputError(source, where + ".axes",
                                 "is " + typeName(axes) + ", not an object of value lists");
            // nlohmann's object keeps keys sorted; the order of the axes is that order.
            for (const auto& [name, values] : axes.items()) {
                const std::string f = where + ".axes." + name;
                if (!values.is_array() || values.empty())
                    throw InputError(source, f, "must be a non-empty array of values",
                                     "e.g. [16, 64, 256]");
                run.axes.emplace_back(name, std::vector<json>(values.begin(), values.end()));
            }
        }
        if (r.contains("combine")) {
            const json& c = r["combine"];
            if (!c.is_string() || (c != "one-at-a-time" && c != "grid"))
                throw InputError(source, where + ".combine",
                                 "must be \"one-at-a-time\" or \"grid\"");
            run.grid = c == "grid";
        }
        if (r.contains("reference")) {
            const SweepReferenceSpec ref =
                parseReference(r["reference"], source, where + ".reference");
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
    pipeline::RunResult r = references_.run(s, {}, progress);
    SweepReference ref;
    ref.linear = std::move(r.image);
    ref.display = displayOf(ref.linear, s);
    const json& pt = r.details.contains("pathtrace") ? r.details["pathtrace"] : json::object();
    ref.relativeStdError = pt.value("relative_std_error", std::numeric_limits<double>::quiet_NaN());
    ref.spp = pt.value("spp", 0LL);
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
    pipeline::RunResult r =
        variants_.run(s, {.frames = item.method == "pathtrace" ? 1 : spec_.frames}, progress);
    SweepRow row;
    row.item = item;
    row.warnings = r.warnings;
    row.referenceError = ref.relativeStdError;
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
