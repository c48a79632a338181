// SPDX-License-Identifier: MIT
#pragma once
// Methods: a name, the effects it can simulate, and a planner that parses its params and returns
// the stages it needs. A method is one module registering itself with a static RegisterMethod
// object (the pipeline is built as an object library so no registration is dropped by the
// linker); io/ knows no method names, render/ no scene keys, app/ only asks the registry.
//
// Effects (the scene's "effects" list) are what the user asks to see. Absent: the method's
// defaults. Present: every name must be one the method simulates (InputError otherwise, naming the
// registered methods that do), and effects the method could add but the list omits are turned
// off — their stages are planned as "not needed".
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "io/scene.h"
#include "pipeline/pipeline.h"

namespace voxlight::pipeline {

/// Strict reader of `method.params`: unknown keys, wrong types and out-of-range values are an
/// InputError naming "method.params.<key>" and the allowed keys; `used` collects every parameter
/// with its value as used (defaults filled in) for the stats.
class ParamReader {
  public:
    ParamReader(const io::Scene& scene, std::vector<std::string> allowed);
    double number(const std::string& key, double def, double lo, double hi);
    int integer(const std::string& key, int def, int lo, int hi);
    bool boolean(const std::string& key, bool def);
    std::string choice(const std::string& key, const std::string& def,
                       const std::vector<std::string>& allowed);
    bool has(const std::string& key) const { return params_.contains(key); }
    [[noreturn]] void fail(const std::string& key, const std::string& problem,
                           const std::string& fix = {}) const;
    nlohmann::json used = nlohmann::json::object();

  private:
    const io::Scene& scene_;
    const nlohmann::json& params_;
};

struct EffectInfo {
    std::string name;
    std::string meaning;
};
/// Every effect name a scene may ask for, with what it means.
const std::vector<EffectInfo>& effectCatalog();

struct MethodInfo {
    std::string name;
    std::string summary;
    std::vector<std::string> effects;  ///< effect names it can simulate
    std::vector<std::string> params;   ///< the keys method.params may hold
    /// Plans the scene's stages, reading method.params through `reader` (which has already
    /// refused keys not in `params`). Throws InputError.
    std::function<Plan(const io::Scene&, ParamReader&)> plan;
};

class MethodRegistry {
  public:
    static MethodRegistry& instance();
    /// InternalError on a duplicate name.
    void add(MethodInfo info);
    const MethodInfo* find(const std::string& name) const;
    std::vector<std::string> names() const;
    const std::vector<MethodInfo>& methods() const { return methods_; }

  private:
    std::vector<MethodInfo> methods_;
};

struct RegisterMethod {
    explicit RegisterMethod(MethodInfo info) { MethodRegistry::instance().add(std::move(info)); }
};

/// Whether the scene asks for `effect`: its effects list names it, or there is no list.
bool wantsEffect(const io::Scene& scene, const std::string& effect);

}  // namespace voxlight::pipeline
