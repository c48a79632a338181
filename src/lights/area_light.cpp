// SPDX-License-Identifier: MIT
#include "lights/area_light.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <sstream>

#include "core/error.h"
#include "sh/sh_basis.h"
#include "sh/sh_projection.h"
#include "sh/sh_window.h"

namespace voxlight::lights {

namespace {
constexpr double kPi = std::numbers::pi;

// Orthonormal tangents of a unit normal (Duff et al. 2017).
void tangents(const glm::dvec3& n, glm::dvec3& t1, glm::dvec3& t2) {
    const double s = std::copysign(1.0, n.z);
    const double a = -1.0 / (s + n.z), b = n.x * n.y * a;
    t1 = {1.0 + s * n.x * n.x * a, s * b, -s * n.x};
    t2 = {b, s + n.y * n.y * a, -n.y};
}

std::string v3(const glm::dvec3& v) {
    std::ostringstream os;
    os << "(" << v.x << ", " << v.y << ", " << v.z << ")";
    return os.str();
}
}  // namespace

// ---- Sphere
// ----------------------------------------------------------------------------------------------------

SphereLight::SphereLight(const glm::vec3& radiance, const glm::dvec3& centre, double radius)
    : le_(radiance), c_(centre), r_(radius) {
    checkRadiometric(radiance, "radiance");
    checkFinitePoint(centre, "centre");
    checkPositive(radius, "radius");
}

void SphereLight::cone(const glm::dvec3& x, double& cosAlpha, double& oneMinusCos) const {
    const double d2 = glm::dot(c_ - x, c_ - x), r2 = r_ * r_;
    if (d2 <= r2) {
        cosAlpha = -1.0, oneMinusCos = 2.0;
        return;
    }
    const double sin2 = r2 / d2;
    cosAlpha = std::sqrt(1.0 - sin2);
    oneMinusCos = sin2 / (1.0 + cosAlpha);
}

double SphereLight::solidAngle(const glm::dvec3& x) const {
    double c, omc;
    cone(x, c, omc);
    return 2.0 * kPi * omc;
}

double SphereLight::hitDistance(const glm::dvec3& x, const glm::dvec3& wi) const {
    const glm::dvec3 oc = x - c_;
    const double b = glm::dot(oc, wi), cc = glm::dot(oc, oc) - r_ * r_;
    const double disc = std::max(0.0, b * b - cc);
    const double s = std::sqrt(disc);
    const double t0 = -b - s, t1 = -b + s;
    return t0 > 0 ? t0 : std::max(t1, 0.0);
}

LightSample SphereLight::sample(const glm::dvec3& x, const glm::vec2& u) const {
    double cosA, omc;
    cone(x, cosA, omc);
    LightSample s;
    glm::dvec3 w = c_ - x;
    const double d = glm::length(w);
    w = d > 0 ? w / d : glm::dvec3(0, 0, 1);
    glm::dvec3 t1, t2;
    tangents(w, t1, t2);
    const double cosT = 1.0 - u.x * omc;  // uniform in the cone (or the whole sphere when inside)
    const double sinT = std::sqrt(std::max(0.0, 1.0 - cosT * cosT));
    const double phi = 2.0 * kPi * u.y;
    const glm::dvec3 wi =
        glm::normalize(cosT * w + sinT * (std::cos(phi) * t1 + std::sin(phi) * t2));
    s.wi = glm::vec3(wi);
    s.value = le_;
    s.pdf = float(1.0 / (2.0 * kPi * omc));
    s.distance = float(hitDistance(x, wi));
    return s;
}

float SphereLight::pdf(const glm::dvec3& x, const glm::vec3& wi) const {
    double cosA, omc;
    cone(x, cosA, omc);
    if (omc >= 2.0) return float(1.0 / (4.0 * kPi));
    const glm::dvec3 w = glm::normalize(c_ - x);
    return glm::dot(glm::dvec3(wi), w) >= cosA ? float(1.0 / (2.0 * kPi * omc)) : 0.0f;
}

glm::vec3 SphereLight::radiance(const glm::dvec3& x, const glm::vec3& wi) const {
    return pdf(x, wi) > 0 ? le_ : glm::vec3(0.0f);
}

void SphereLight::writeSh(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const {
    double cosA, omc;
    cone(x, cosA, omc);
    // Zonal coefficients of the cap indicator (radiance 1) about +z, then aligned with the axis
    // toward the centre.
    std::array<double, sh::kMaxBand + 1> z;
    for (int l = 0; l <= maxBand; ++l) {
        const double integral =
            l == 0 ? omc
                   : (std::legendre(l - 1, cosA) - std::legendre(l + 1, cosA)) / (2.0 * l + 1.0);
        z[l] = 2.0 * kPi * std::sqrt((2.0 * l + 1.0) / (4.0 * kPi)) * integral;
    }
    const glm::dvec3 axis = glm::length(c_ - x) > 0 ? c_ - x : glm::dvec3(0, 0, 1);
    std::array<float, sh::kMaxCoeffs> unit;
    sh::zonalToAxis(std::span<const double>(z.data(), maxBand + 1), axis, unit);
    for (std::size_t i = 0; i < out.size(); ++i) out[i] = le_ * unit[i];
}

void SphereLight::writeDsf(const glm::dvec3& x, const sh::Dsf& dsf,
                           std::span<glm::vec3> out) const {
    double cosA, omc;
    cone(x, cosA, omc);
    glm::dvec3 w = c_ - x;
    w = glm::length(w) > 0 ? glm::normalize(w) : glm::dvec3(0, 0, 1);
    glm::dvec3 t1, t2;
    tangents(w, t1, t2);
    // Equal-solid-angle cells of the cone (midpoints in cos θ and φ), each a small directional
    // source.
    constexpr int kRings = 16, kSectors = 32;
    const double cellOmega = 2.0 * kPi * omc / (kRings * kSectors);
    std::fill(out.begin(), out.end(), glm::vec3(0.0f));
    for (int i = 0; i < kRings; ++i) {
        const double cosT = 1.0 - (i + 0.5) / kRings * omc;
        const double sinT = std::sqrt(std::max(0.0, 1.0 - cosT * cosT));
        for (int j = 0; j < kSectors; ++j) {
            const double phi = 2.0 * kPi * (j + 0.5) / kSectors;
            const glm::dvec3 wi = cosT * w + sinT * (std::cos(phi) * t1 + std::sin(phi) * t2);
            dsf.addDirectional(out, glm::normalize(wi), le_ * float(cellOmega));
        }
    }
}

std::string SphereLight::toString() const {
    std::ostringstream os;
    os << "SphereLight{Le=" << v3(le_) << ", centre=" << v3(c_) << " mm, radius=" << r_ << " mm}";
    return os.str();
}

// ---- Planar (rectangle, disk)
// ----------------------------------------------------------------------------------

PlanarLight::PlanarLight(const glm::vec3& radiance, const glm::dvec3& normal, double area)
    : le_(radiance), n_(normal), area_(area) {
    checkRadiometric(radiance, "radiance");
}

void PlanarLight::setQuadratureResolution(int cellsPerSide) {
    if (cellsPerSide < 1 || cellsPerSide > 4096)
        throw InputError("light", "quadrature_resolution",
                         "must be in 1..4096, got " + std::to_string(cellsPerSide), "use e.g. 32");
    resolution_ = cellsPerSide;
}

double PlanarLight::hit(const glm::dvec3& x, const glm::dvec3& wi) const {
    const double denom = glm::dot(wi, n_);
    if (!(denom < 0)) return -1.0;  // parallel or seeing the back face
    const double t = glm::dot(anchor() - x, n_) / denom;
    if (!(t > 0)) return -1.0;
    return contains(x + t * wi) ? t : -1.0;
}

LightSample PlanarLight::sample(const glm::dvec3& x, const glm::vec2& u) const {
    LightSample s;
    const glm::dvec3 y = pointAt(u.x, u.y);
    const glm::dvec3 v = y - x;
    const double d2 = glm::dot(v, v), d = std::sqrt(d2);
    if (!(d > 0)) return s;
    const glm::dvec3 wi = v / d;
    const double cosL = -glm::dot(wi, n_);
    if (!(cosL > 0)) return s;  // behind the emitter
    s.wi = glm::vec3(wi);
    s.value = le_;
    s.pdf = float(d2 / (area_ * cosL));
    s.distance = float(d);
    return s;
}

float PlanarLight::pdf(const glm::dvec3& x, const glm::vec3& wiF) const {
    const glm::dvec3 wi = glm::normalize(glm::dvec3(wiF));
    const double t = hit(x, wi);
    if (t <= 0) return 0.0f;
    return float(t * t / (area_ * -glm::dot(wi, n_)));
}

glm::vec3 PlanarLight::radiance(const glm::dvec3& x, const glm::vec3& wi) const {
    return hit(x, glm::normalize(glm::dvec3(wi))) > 0 ? le_ : glm::vec3(0.0f);
}

template <class Add>
void PlanarLight::quadrature(const glm::dvec3& x, Add&& add) const {
    const int n = resolution_;
    const double cellArea = area_ / (double(n) * n);
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            const glm::dvec3 v = pointAt((i + 0.5) / n, (j + 0.5) / n) - x;
            const double d2 = glm::dot(v, v);
            if (!(d2 > 0)) continue;
            const glm::dvec3 wi = v / std::sqrt(d2);
            const double cosL = -glm::dot(wi, n_);
            if (cosL <= 0) continue;
            add(wi, le_ * float(cosL * cellArea / d2));  // irradiance of the cell = Le · dω
        }
}

void PlanarLight::writeSh(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const {
    // Double sums on the stack (no allocation per voxel).
    std::array<glm::dvec3, sh::kMaxCoeffs> sum;
    const std::span<glm::dvec3> acc(sum.data(), out.size());
    std::fill(acc.begin(), acc.end(), glm::dvec3(0.0));
    quadrature(x, [&](const glm::dvec3& wi, const glm::vec3& e) {
        sh::addShSample(maxBand, wi, glm::dvec3(e), acc);
    });
    for (std::size_t i = 0; i < out.size(); ++i) out[i] = glm::vec3(acc[i]);
}

void PlanarLight::writeDsf(const glm::dvec3& x, const sh::Dsf& dsf,
                           std::span<glm::vec3> out) const {
    std::fill(out.begin(), out.end(), glm::vec3(0.0f));
    quadrature(x,
               [&](const glm::dvec3& wi, const glm::vec3& e) { dsf.addDirectional(out, wi, e); });
}

RectLight::RectLight(const glm::vec3& radiance, const glm::dvec3& corner, const glm::dvec3& edgeU,
                     const glm::dvec3& edgeV)
    : PlanarLight(radiance, glm::dvec3(0, 0, 1), glm::length(glm::cross(edgeU, edgeV))),
      p0_(corner),
      eu_(edgeU),
      ev_(edgeV) {
    checkFinitePoint(corner, "corner");
    checkFinitePoint(edgeU, "edge_u");
    checkFinitePoint(edgeV, "edge_v");
    const double lu = glm::length(edgeU), lv = glm::length(edgeV);
    if (!(area_ > 0) || !(lu > 0) || !(lv > 0))
        throw InputError("light", "edge_u/edge_v",
                         "rectangle edges " + v3(edgeU) + " and " + v3(edgeV) + " span no area",
                         "give two non-parallel, non-zero edge vectors in mm");
    if (std::abs(glm::dot(edgeU, edgeV)) > 1e-6 * lu * lv)
        throw InputError("light", "edge_u/edge_v", "rectangle edges are not perpendicular",
                         "give perpendicular edge vectors (for a parallelogram use two lights)");
    n_ = glm::normalize(glm::cross(edgeU, edgeV));
}

bool RectLight::contains(const glm::dvec3& p) const {
    const glm::dvec3 q = p - p0_;
    const double u = glm::dot(q, eu_) / glm::dot(eu_, eu_),
                 v = glm::dot(q, ev_) / glm::dot(ev_, ev_);
    return u >= 0 && u <= 1 && v >= 0 && v <= 1;
}

std::string RectLight::toString() const {
    std::ostringstream os;
    os << "RectLight{Le=" << v3(le_) << ", corner=" << v3(p0_) << ", u=" << v3(eu_)
       << ", v=" << v3(ev_) << "}";
    return os.str();
}

DiskLight::DiskLight(const glm::vec3& radiance, const glm::dvec3& centre, const glm::dvec3& normal,
                     double radius)
    : PlanarLight(radiance, sh::normalizeDirection(normal, "light", "normal"),
                  kPi * radius * radius),
      c_(centre),
      r_(radius) {
    checkFinitePoint(centre, "centre");
    checkPositive(radius, "radius");
    tangents(n_, t1_, t2_);
}

glm::dvec3 DiskLight::pointAt(double u, double v) const {
    const double r = r_ * std::sqrt(u), phi = 2.0 * kPi * v;  // area-preserving polar map
    return c_ + r * (std::cos(phi) * t1_ + std::sin(phi) * t2_);
}

std::string DiskLight::toString() const {
    std::ostringstream os;
    os << "DiskLight{Le=" << v3(le_) << ", centre=" << v3(c_) << ", normal=" << v3(n_)
       << ", radius=" << r_ << "}";
    return os.str();
}

}  // namespace voxlight::lights
