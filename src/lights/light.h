// SPDX-License-Identifier: MIT
#pragma once
// Light sources: one interface for the path tracer (sampling, pdf, radiance along a ray) and for
// the precomputed methods (SH and DSF coefficients of the incident radiance at a point).
//
// Units and conventions (ARCHITECTURE §1, §3): positions in mm (world = patient LPS), directions
// unit vectors. `wi` / `towardLight` always point *from the shaded point toward the light*, like ω
// in V(x, ω). Radiance L is RGB in the scene's radiometric unit; irradiance E = ∫ L dω over the
// light [L·sr]; point-light intensity I gives E = I / d² [I in L·sr·mm²]. SH coefficients
// (sh/sh_basis.h conventions): c_i = ∫ L_in(x, ω) Y_i(ω) dω, (L+1)² RGB entries; a directional
// light gives E·Y_i(ω_l) (Kronander eq. 10). DSF coefficients (sh/dsf.h): radiance samples s_k with
// Σ_k A_k s_k = ∫ L_in dω; delta lights use the barycentric blend of Zhang §5.2.
//
// Bad parameters (zero direction, negative or non-finite power, radius ≤ 0 …) → InputError naming
// the light field.
#include <glm/glm.hpp>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "sh/dsf.h"

namespace voxlight::lights {

/// One light sample seen from a point.
struct LightSample {
    glm::vec3 wi{0.0f};  ///< unit direction toward the light
    /// Radiance L along wi; for delta lights the irradiance E (pdf is then 1).
    glm::vec3 value{0.0f};
    float pdf = 0.0f;  ///< solid-angle density of wi; 0 = no contribution (sample invalid)
    /// To the light [mm] (shadow-ray length).
    float distance = std::numeric_limits<float>::infinity();
    /// Directional/point light: value is irradiance, wi was not drawn from a density.
    bool delta = false;
};

class Light {
  public:
    virtual ~Light() = default;
    virtual std::string_view kind() const = 0;
    /// Directional and point lights: cannot be hit by a ray, sample() is exact (pdf 1, delta =
    /// true).
    virtual bool isDelta() const = 0;
    /// Sample the light as seen from x, with u ∈ [0,1)².
    virtual LightSample sample(const glm::dvec3& x, const glm::vec2& u) const = 0;
    /// Solid-angle pdf with which sample() draws wi from x (0 for delta lights and for directions
    /// missing the light).
    virtual float pdf(const glm::dvec3& x, const glm::vec3& wi) const = 0;
    /// Radiance arriving at x from direction wi (0 for delta lights or if the light is not hit).
    virtual glm::vec3 radiance(const glm::dvec3& x, const glm::vec3& wi) const = 0;
    /// SH coefficients of the incident radiance at x, bands 0..maxBand, written to `out`, which
    /// must hold exactly shCount(maxBand) entries (VL_CHECK). Allocation-free for the directional,
    /// point and area lights (per-voxel use); a bad band → InputError.
    void shCoefficients(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const;
    /// The same as a new vector (allocates; for setup code and tests).
    std::vector<glm::vec3> shCoefficients(const glm::dvec3& x, int maxBand) const;
    /// DSF coefficients of the incident radiance at x, written to `out` (exactly dsf.size()
    /// entries, VL_CHECK). Allocation-free for the directional, point and area lights.
    void dsfCoefficients(const glm::dvec3& x, const sh::Dsf& dsf, std::span<glm::vec3> out) const;
    /// The same as a new vector (allocates).
    std::vector<glm::vec3> dsfCoefficients(const glm::dvec3& x, const sh::Dsf& dsf) const;
    virtual std::string toString() const = 0;

  protected:
    /// Names the light in the InputError for a bad band.
    virtual const char* errorSource() const { return "light"; }

  private:
    // Implementations behind the public overloads: the band is valid and `out` has the right size;
    // every entry must be overwritten.
    virtual void writeSh(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const = 0;
    virtual void writeDsf(const glm::dvec3& x, const sh::Dsf& dsf,
                          std::span<glm::vec3> out) const = 0;
};

/// Distant light from a fixed direction. E = irradiance on a surface facing the light.
class DirectionalLight final : public Light {
  public:
    DirectionalLight(const glm::vec3& irradiance, const glm::vec3& towardLight);
    const glm::vec3& irradiance() const { return e_; }
    const glm::vec3& direction() const { return dir_; }

    std::string_view kind() const override { return "directional"; }
    bool isDelta() const override { return true; }
    LightSample sample(const glm::dvec3& x, const glm::vec2& u) const override;
    float pdf(const glm::dvec3&, const glm::vec3&) const override { return 0.0f; }
    glm::vec3 radiance(const glm::dvec3&, const glm::vec3&) const override {
        return glm::vec3(0.0f);
    }
    std::string toString() const override;

  private:
    void writeSh(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const override;
    void writeDsf(const glm::dvec3& x, const sh::Dsf& dsf, std::span<glm::vec3> out) const override;
    glm::vec3 e_, dir_;
};

/// Isotropic point light. E(x) = I / max(d, minDistance)²: within minDistance of the light the
/// irradiance is clamped, so samples at (or next to) the light stay finite. The SH/DSF direction of
/// a point light is undefined at d = 0: for d < minDistance the incident radiance blends linearly
/// from the delta toward the light (weight d/minDistance) to a uniform radiance with the same
/// irradiance, E/(4π) from every direction (weight 1 − d/minDistance) — continuous in x and exactly
/// isotropic at the light.
class PointLight final : public Light {
  public:
    PointLight(const glm::vec3& intensity, const glm::dvec3& position, double minDistance = 1.0);
    const glm::vec3& intensity() const { return i_; }
    const glm::dvec3& position() const { return p_; }
    double minDistance() const { return rmin_; }
    /// Irradiance at x facing the light (with the clamp).
    glm::vec3 irradianceAt(const glm::dvec3& x) const;

    std::string_view kind() const override { return "point"; }
    bool isDelta() const override { return true; }
    LightSample sample(const glm::dvec3& x, const glm::vec2& u) const override;
    float pdf(const glm::dvec3&, const glm::vec3&) const override { return 0.0f; }
    glm::vec3 radiance(const glm::dvec3&, const glm::vec3&) const override {
        return glm::vec3(0.0f);
    }
    std::string toString() const override;

  private:
    void writeSh(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const override;
    void writeDsf(const glm::dvec3& x, const sh::Dsf& dsf, std::span<glm::vec3> out) const override;
    glm::vec3 i_;
    glm::dvec3 p_;
    double rmin_;
};

/// Validation helpers shared by the light constructors (InputError with source "light", the given
/// field).
void checkRadiometric(const glm::vec3& v, const char* field);
void checkPositive(double v, const char* field);
void checkFinitePoint(const glm::dvec3& p, const char* field);

}  // namespace voxlight::lights
