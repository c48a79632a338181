// SPDX-License-Identifier: MIT
#include "pvrt/basis.h"

#include <algorithm>
#include <map>
#include <mutex>

#include "core/error.h"
#include "sh/sh_basis.h"

namespace voxlight::pvrt {

Basis Basis::sh(int order, const char* field) {
    if (order < 1 || order > kMaxShOrder)
        throw InputError(
            "pvrt", field,
            "SH order " + std::to_string(order) + " is outside 1…" + std::to_string(kMaxShOrder),
            "use an order from 1 (1 basis light) to 6 (36 basis lights)");
    Basis b;
    b.kind_ = BasisKind::Sh;
    b.band_ = order - 1;
    b.size_ = sh::shCount(b.band_);
    return b;
}

Basis Basis::dsf(int count, const char* field) {
    if (count != 42 && count != 162 && count != 642)
        throw InputError("pvrt", field,
                         "DSF with " + std::to_string(count) + " directions is not offered",
                         "use 42, 162 or 642 directions");
    // A DSF's direction set and lookup lists take ~10 ms to build (642): built once per process
    // and shared, so a light change (which makes its Basis again) does not pay for it.
    static std::mutex mutex;
    static std::map<int, std::shared_ptr<const sh::Dsf>> built;
    Basis b;
    b.kind_ = BasisKind::Dsf;
    {
        const std::lock_guard lock(mutex);
        auto& d = built[count];
        if (!d) d = std::make_shared<const sh::Dsf>(count);
        b.dsf_ = d;
    }
    b.size_ = count;
    return b;
}

std::string Basis::name() const {
    return (kind_ == BasisKind::Sh ? "sh" : "dsf") + std::to_string(size_);
}

int Basis::maxSupport() const { return kind_ == BasisKind::Sh ? size_ : sh::Dsf::kMaxSupport; }

int Basis::evaluate(const glm::dvec3& unitDir, int* index, float* value) const {
    if (kind_ == BasisKind::Sh) {
        double y[sh::shCount(kMaxShOrder - 1)];
        sh::evalShUnitDouble(band_, unitDir, std::span<double>(y, std::size_t(size_)));
        for (int k = 0; k < size_; ++k) {
            index[k] = k;
            value[k] = float(y[k]);
        }
        return size_;
    }
    double w[sh::Dsf::kMaxSupport];
    const int n = dsf_->weights(unitDir, index, w);
    for (int i = 0; i < n; ++i) value[i] = float(w[i]);
    return n;
}

std::vector<glm::vec3> Basis::project(
    std::span<const std::shared_ptr<const lights::Light>> lights) const {
    std::vector<glm::vec3> sum(std::size_t(size_), glm::vec3(0.f));
    std::vector<glm::vec3> one(sum.size());
    for (std::size_t i = 0; i < lights.size(); ++i) {
        const lights::Light& light = *lights[i];
        if (light.kind() != "directional" && light.kind() != "environment")
            throw InputError(
                "scene", "lights[" + std::to_string(i) + "]",
                "a " + std::string(light.kind()) +
                    " light is not distant: PVRT precomputes transfer for distant lighting only",
                "use directional or environment lights with method pvrt, or render this scene "
                "with sh-global or pathtrace");
        // Distant lights: the same coefficients at every point; the origin stands for all.
        if (kind_ == BasisKind::Sh)
            light.shCoefficients(glm::dvec3(0.0), band_, one);
        else
            light.dsfCoefficients(glm::dvec3(0.0), *dsf_, one);
        for (std::size_t k = 0; k < sum.size(); ++k) sum[k] += one[k];
    }
    return sum;
}

}  // namespace voxlight::pvrt
