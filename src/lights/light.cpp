// SPDX-License-Identifier: MIT
#include "lights/light.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <sstream>

#include "core/error.h"
#include "sh/sh_basis.h"

namespace voxlight::lights {

namespace {
std::string vecString(const glm::dvec3& v) {
    std::ostringstream os;
    os << "(" << v.x << ", " << v.y << ", " << v.z << ")";
    return os.str();
}

// out[i] = E · Y_i(dir), i < shCount(maxBand) (band already checked), without allocating.
void deltaSh(const glm::vec3& e, const glm::dvec3& dir, int maxBand, std::span<glm::vec3> out) {
    std::array<double, sh::kMaxCoeffs> y;
    sh::evalShUnitDouble(maxBand, dir, y);
    for (int i = 0; i < sh::shCount(maxBand); ++i) out[i] = e * float(y[i]);
}
}  // namespace

// ---- Light: the public overloads check, then call the implementation ---------------------------

void Light::shCoefficients(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const {
    sh::checkBand(maxBand, errorSource(), "sh bands");
    VL_CHECK_EQ(out.size(), std::size_t(sh::shCount(maxBand)));
    writeSh(x, maxBand, out);
}

std::vector<glm::vec3> Light::shCoefficients(const glm::dvec3& x, int maxBand) const {
    sh::checkBand(maxBand, errorSource(), "sh bands");
    std::vector<glm::vec3> c(sh::shCount(maxBand));
    writeSh(x, maxBand, c);
    return c;
}

void Light::dsfCoefficients(const glm::dvec3& x, const sh::Dsf& dsf,
                            std::span<glm::vec3> out) const {
    VL_CHECK_EQ(out.size(), std::size_t(dsf.size()));
    writeDsf(x, dsf, out);
}

std::vector<glm::vec3> Light::dsfCoefficients(const glm::dvec3& x, const sh::Dsf& dsf) const {
    std::vector<glm::vec3> s(dsf.size());
    writeDsf(x, dsf, s);
    return s;
}

void checkRadiometric(const glm::vec3& v, const char* field) {
    for (int c = 0; c < 3; ++c)
        if (!std::isfinite(v[c]) || v[c] < 0)
            throw InputError("light", field,
                             "must be finite and ≥ 0 in every channel, got " + vecString(v),
                             "give a non-negative RGB value");
}

void checkPositive(double v, const char* field) {
    if (!(v > 0) || !std::isfinite(v))
        throw InputError("light", field,
                         "must be a finite positive number, got " + std::to_string(v),
                         "give a value > 0 (millimetres)");
}

void checkFinitePoint(const glm::dvec3& p, const char* field) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        throw InputError("light", field, "must be a finite point, got " + vecString(p),
                         "give finite coordinates in mm");
}

// ---- Directional
// -----------------------------------------------------------------------------------------------

DirectionalLight::DirectionalLight(const glm::vec3& irradiance, const glm::vec3& towardLight)
    : e_(irradiance), dir_(sh::normalizeDirection(towardLight, "light", "direction")) {
    checkRadiometric(irradiance, "irradiance");
}

LightSample DirectionalLight::sample(const glm::dvec3&, const glm::vec2&) const {
    LightSample s;
    s.wi = dir_;
    s.value = e_;
    s.pdf = 1.0f;
    s.delta = true;
    return s;
}

void DirectionalLight::writeSh(const glm::dvec3&, int maxBand, std::span<glm::vec3> out) const {
    deltaSh(e_, glm::dvec3(dir_), maxBand, out);
}

void DirectionalLight::writeDsf(const glm::dvec3&, const sh::Dsf& dsf,
                                std::span<glm::vec3> out) const {
    std::fill(out.begin(), out.end(), glm::vec3(0.0f));
    dsf.addDirectional(out, glm::dvec3(dir_), e_);
}

std::string DirectionalLight::toString() const {
    std::ostringstream os;
    os << "DirectionalLight{E=" << vecString(e_) << ", toward=" << vecString(dir_) << "}";
    return os.str();
}

// ---- Point
// -----------------------------------------------------------------------------------------------------

PointLight::PointLight(const glm::vec3& intensity, const glm::dvec3& position, double minDistance)
    : i_(intensity), p_(position), rmin_(minDistance) {
    checkRadiometric(intensity, "intensity");
    checkFinitePoint(position, "position");
    checkPositive(minDistance, "min_distance");
}

glm::vec3 PointLight::irradianceAt(const glm::dvec3& x) const {
    const double d = std::max(glm::length(p_ - x), rmin_);
    return i_ * float(1.0 / (d * d));
}

LightSample PointLight::sample(const glm::dvec3& x, const glm::vec2&) const {
    LightSample s;
    const glm::dvec3 v = p_ - x;
    const double d = glm::length(v);
    s.delta = true;
    if (!(d > 0)) return s;  // at the light: no direction, pdf 0
    s.wi = glm::vec3(v / d);
    s.value = irradianceAt(x);
    s.pdf = 1.0f;
    s.distance = float(d);
    return s;
}

void PointLight::writeSh(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const {
    const glm::vec3 e = irradianceAt(x);
    const double d = glm::length(p_ - x);
    const double directional = std::min(1.0, d / rmin_);
    if (directional > 0)
        deltaSh(e * float(directional), (p_ - x) / d, maxBand, out);
    else
        std::fill(out.begin(), out.end(), glm::vec3(0.0f));
    // Uniform part: radiance E/(4π) everywhere projects to c_0 = E/(4π)·√(4π) = E/√(4π).
    out[0] += e * float((1.0 - directional) / std::sqrt(4.0 * std::numbers::pi));
}

void PointLight::writeDsf(const glm::dvec3& x, const sh::Dsf& dsf, std::span<glm::vec3> out) const {
    const glm::vec3 e = irradianceAt(x);
    const double d = glm::length(p_ - x);
    const double directional = std::min(1.0, d / rmin_);
    std::fill(out.begin(), out.end(), e * float((1.0 - directional) / (4.0 * std::numbers::pi)));
    if (directional > 0) dsf.addDirectional(out, (p_ - x) / d, e * float(directional));
}

std::string PointLight::toString() const {
    std::ostringstream os;
    os << "PointLight{I=" << vecString(i_) << ", position=" << vecString(p_)
       << " mm, min_distance=" << rmin_ << " mm}";
    return os.str();
}

}  // namespace voxlight::lights
