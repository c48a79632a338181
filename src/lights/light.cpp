// SPDX-License-Identifier: MIT
#include "lights/light.h"

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

std::vector<glm::vec3> deltaSh(const glm::vec3& e, const glm::dvec3& dir, int maxBand) {
    sh::checkBand(maxBand, "light", "sh bands");
    std::vector<double> y(sh::shCount(maxBand));
    sh::evalShUnitDouble(maxBand, dir, y);
    std::vector<glm::vec3> c(y.size());
    for (std::size_t i = 0; i < y.size(); ++i) c[i] = e * float(y[i]);
    return c;
}
}  // namespace

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

std::vector<glm::vec3> DirectionalLight::shCoefficients(const glm::dvec3&, int maxBand) const {
    return deltaSh(e_, glm::dvec3(dir_), maxBand);
}

std::vector<glm::vec3> DirectionalLight::dsfCoefficients(const glm::dvec3&,
                                                         const sh::Dsf& dsf) const {
    std::vector<glm::vec3> s(dsf.size(), glm::vec3(0.0f));
    dsf.addDirectional(s, glm::dvec3(dir_), e_);
    return s;
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

std::vector<glm::vec3> PointLight::shCoefficients(const glm::dvec3& x, int maxBand) const {
    // Checked here, not only in deltaSh: at the light (directional == 0) deltaSh is skipped and
    // c[0] below would index an empty vector for a negative band.
    sh::checkBand(maxBand, "light", "sh bands");
    const glm::vec3 e = irradianceAt(x);
    const double d = glm::length(p_ - x);
    const double directional = std::min(1.0, d / rmin_);
    std::vector<glm::vec3> c = directional > 0
                                   ? deltaSh(e * float(directional), (p_ - x) / d, maxBand)
                                   : std::vector<glm::vec3>(sh::shCount(maxBand), glm::vec3(0.0f));
    // Uniform part: radiance E/(4π) everywhere projects to c_0 = E/(4π)·√(4π) = E/√(4π).
    c[0] += e * float((1.0 - directional) / std::sqrt(4.0 * std::numbers::pi));
    return c;
}

std::vector<glm::vec3> PointLight::dsfCoefficients(const glm::dvec3& x, const sh::Dsf& dsf) const {
    const glm::vec3 e = irradianceAt(x);
    const double d = glm::length(p_ - x);
    const double directional = std::min(1.0, d / rmin_);
    std::vector<glm::vec3> s(dsf.size(), e * float((1.0 - directional) / (4.0 * std::numbers::pi)));
    if (directional > 0) dsf.addDirectional(s, (p_ - x) / d, e * float(directional));
    return s;
}

std::string PointLight::toString() const {
    std::ostringstream os;
    os << "PointLight{I=" << vecString(i_) << ", position=" << vecString(p_)
       << " mm, min_distance=" << rmin_ << " mm}";
    return os.str();
}

}  // namespace voxlight::lights
