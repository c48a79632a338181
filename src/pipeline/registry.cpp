// SPDX-License-Identifier: MIT
#include "pipeline/registry.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "io/json_field.h"

namespace voxlight::pipeline {

using nlohmann::json;

namespace {}  // namespace

ParamReader::ParamReader(const io::Scene& scene, std::vector<std::string> allowed)
    : scene_(scene), params_(scene.method.params) {
    for (auto it = params_.begin(); it != params_.end(); ++it)
        if (std::find(allowed.begin(), allowed.end(), it.key()) == allowed.end())
            fail(it.key(), "is not a parameter of method '" + scene_.method.name + "'",
                 "allowed: " + joinNames(allowed));
}

void ParamReader::fail(const std::string& key, const std::string& problem,
                       const std::string& fix) const {
    throw InputError(scene_.source, "method.params." + key, problem, fix);
}

double ParamReader::number(const std::string& k, double def, double lo, double hi) {
    double v = def;
    if (params_.contains(k)) {
        const json& j = params_[k];
        if (!j.is_number()) fail(k, "must be a number, got " + io::described(j));
        v = j.get<double>();
        if (!std::isfinite(v) || v < lo || v > hi) {
            std::ostringstream os;
            os << "must be in [" << lo << ", " << hi << "], got " << io::numberAsWritten(j);
            fail(k, os.str());
        }
    }
    used[k] = v;
    return v;
}

int ParamReader::integer(const std::string& k, int def, int lo, int hi) {
    int v = def;
    if (params_.contains(k)) {
        const json& j = params_[k];
        const std::string range =
            "must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got ";
        // A whole number written as 64.0 or 1e3 is an integer (JSON has one number type).
        const bool whole = j.is_number_float() && std::isfinite(j.get<double>()) &&
                           j.get<double>() == std::floor(j.get<double>());
        if (whole && (j.get<double>() < lo || j.get<double>() > hi))
            fail(k, range + io::numberAsWritten(j));
        if (whole) {
            used[k] = v = int(j.get<double>());
            return v;
        }
        if (!j.is_number_integer() && !j.is_number_unsigned()) fail(k, range + io::described(j));
        // Unsigned values past long long's range wrapped to negatives.
        if (j.is_number_unsigned() &&
            j.get<std::uint64_t>() > std::uint64_t(std::numeric_limits<long long>::max()))
            fail(k, range + io::shortDump(j));
        const long long x = j.get<long long>();
        if (x < lo || x > hi) fail(k, range + std::to_string(x));
        v = int(x);
    }
    used[k] = v;
    return v;
}

bool ParamReader::boolean(const std::string& k, bool def) {
    bool v = def;
    if (params_.contains(k)) {
        if (!params_[k].is_boolean()) fail(k, "must be true or false");
        v = params_[k].get<bool>();
    }
    used[k] = v;
    return v;
}

std::string ParamReader::choice(const std::string& k, const std::string& def,
                                const std::vector<std::string>& allowed) {
    std::string v = def;
    if (params_.contains(k)) {
        if (!params_[k].is_string()) fail(k, "must be a string", "one of: " + joinNames(allowed));
        v = params_[k].get<std::string>();
        if (std::find(allowed.begin(), allowed.end(), v) == allowed.end())
            fail(k, "'" + v + "' is not allowed", "one of: " + joinNames(allowed));
    }
    used[k] = v;
    return v;
}

const std::vector<EffectInfo>& effectCatalog() {
    static const std::vector<EffectInfo> e = {
        {"specular", "highlights: Blinn–Phong specular (gradient), glossy BRDF (path tracer)"},
        {"local_shadows",
         "self-shadowing by matter near each sample, within a radius (SH local visibility, "
         "hierarchical visibility)"},
        {"global_shadows",
         "shadows from matter anywhere between a sample and the light (SH global visibility, "
         "PVRT, path tracer)"},
        {"multiple_scattering",
         "light scattered more than once inside the volume (PVRT, path tracer)"},
        {"depth_of_field", "thin-lens camera blur around a focal distance (path tracer)"},
    };
    return e;
}

MethodRegistry& MethodRegistry::instance() {
    static MethodRegistry r;
    return r;
}

void MethodRegistry::add(MethodInfo info) {
    if (find(info.name)) throw InternalError("method '" + info.name + "' registered twice");
    for (const auto& e : info.effects) {
        const auto& cat = effectCatalog();
        if (std::none_of(cat.begin(), cat.end(), [&](const EffectInfo& c) { return c.name == e; }))
            throw InternalError("method '" + info.name + "' names unknown effect '" + e + "'");
    }
    methods_.push_back(std::move(info));
}

const MethodInfo* MethodRegistry::find(const std::string& name) const {
    for (const auto& m : methods_)
        if (m.name == name) return &m;
    return nullptr;
}

std::vector<std::string> MethodRegistry::names() const {
    std::vector<std::string> n;
    for (const auto& m : methods_) n.push_back(m.name);
    return n;
}

bool wantsEffect(const io::Scene& scene, const std::string& effect) {
    return !scene.effectsGiven ||
           std::find(scene.effects.begin(), scene.effects.end(), effect) != scene.effects.end();
}

}  // namespace voxlight::pipeline
