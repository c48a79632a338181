// SPDX-License-Identifier: MIT
#pragma once
// Area lights for the path tracer (Kroes 2012: plane, disk, sphere emitters) with uniform emitted
// radiance Le. Conventions and units: lights/light.h.
//
// * SphereLight: emits Le outward from every point of its surface. Seen from outside it subtends a
//   cone of half-angle α = asin(r/D); sample() draws uniformly in that cone
//   (pdf 1/(2π(1 − cos α))). From inside (D ≤ r) the incident radiance is Le from every direction
//   (pdf 1/(4π)). SH: closed form (a cap of constant radiance is zonal:
//   z_l = 2π Le √((2l+1)/4π) ∫_{cos α}^1 P_l, with ∫_c^1 P_l = (P_{l−1}(c) − P_{l+1}(c))/(2l+1)).
// * RectLight (corner + two edge vectors) and DiskLight (centre, normal, radius): one-sided,
//   emitting toward the normal n = normalize(edgeU × edgeV) resp. the given normal. sample() picks
//   a uniform point on the emitter (pdf d²/(A cos θ_l) in solid angle); points behind the emitter
//   receive nothing. SH and DSF: midpoint quadrature over `quadratureResolution`² equal-area cells
//   of the emitter, each cell a small directional source of irradiance Le·cos θ_l·ΔA/d² (accurate
//   while the cell is small seen from x: d ≳ 2·size/resolution).
// DSF of every area light: a sum of such small directional sources, each blended barycentrically
// (sh/dsf.h).
#include "lights/light.h"

namespace voxlight::lights {

class SphereLight final : public Light {
  public:
    SphereLight(const glm::vec3& radiance, const glm::dvec3& centre, double radius);
    const glm::dvec3& centre() const { return c_; }
    double radius() const { return r_; }
    /// Radiance leaving the surface (uniform, every direction).
    const glm::vec3& emittedRadiance() const { return le_; }
    /// Solid angle [sr] the sphere subtends at x (4π inside).
    double solidAngle(const glm::dvec3& x) const;

    std::string_view kind() const override { return "sphere"; }
    bool isDelta() const override { return false; }
    LightSample sample(const glm::dvec3& x, const glm::vec2& u) const override;
    float pdf(const glm::dvec3& x, const glm::vec3& wi) const override;
    glm::vec3 radiance(const glm::dvec3& x, const glm::vec3& wi) const override;
    std::string toString() const override;

  private:
    void writeSh(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const override;
    void writeDsf(const glm::dvec3& x, const sh::Dsf& dsf, std::span<glm::vec3> out) const override;
    // cos α and 1 − cos α (computed without cancellation) of the cone seen from x; inside → (−1,
    // 2).
    void cone(const glm::dvec3& x, double& cosAlpha, double& oneMinusCos) const;
    double hitDistance(const glm::dvec3& x, const glm::dvec3& wi) const;
    glm::vec3 le_;
    glm::dvec3 c_;
    double r_;
};

/// Common part of the one-sided planar emitters.
class PlanarLight : public Light {
  public:
    bool isDelta() const override { return false; }
    LightSample sample(const glm::dvec3& x, const glm::vec2& u) const override;
    float pdf(const glm::dvec3& x, const glm::vec3& wi) const override;
    glm::vec3 radiance(const glm::dvec3& x, const glm::vec3& wi) const override;

    double area() const { return area_; }
    const glm::dvec3& normal() const { return n_; }
    /// Radiance leaving the front face (uniform).
    const glm::vec3& emittedRadiance() const { return le_; }
    /// Centre of the emitter (rect: of its parallelogram; disk: its centre).
    virtual glm::dvec3 centre() const = 0;
    /// Cells per side of the SH/DSF quadrature (default 32), ≥ 1.
    void setQuadratureResolution(int cellsPerSide);

  protected:
    PlanarLight(const glm::vec3& radiance, const glm::dvec3& normal, double area);
    /// Point on the emitter for (u, v) ∈ [0,1)², area-preserving (uniform u, v → uniform on the
    /// surface).
    virtual glm::dvec3 pointAt(double u, double v) const = 0;
    /// Whether a point of the emitter's plane lies on the emitter.
    virtual bool contains(const glm::dvec3& p) const = 0;
    virtual glm::dvec3 anchor() const = 0;  ///< any point of the plane
    /// Distance along wi to the emitter if the ray hits its front face, else a negative number.
    double hit(const glm::dvec3& x, const glm::dvec3& wi) const;
    template <class Add>
    void quadrature(const glm::dvec3& x, Add&& add) const;
    void writeSh(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const override;
    void writeDsf(const glm::dvec3& x, const sh::Dsf& dsf, std::span<glm::vec3> out) const override;

    glm::vec3 le_;
    glm::dvec3 n_;
    double area_;
    int resolution_ = 32;
};

class RectLight final : public PlanarLight {
  public:
    /// Emits toward normalize(edgeU × edgeV); InputError if the edges are degenerate or not
    /// perpendicular.
    RectLight(const glm::vec3& radiance, const glm::dvec3& corner, const glm::dvec3& edgeU,
              const glm::dvec3& edgeV);
    std::string_view kind() const override { return "rectangle"; }
    std::string toString() const override;
    glm::dvec3 centre() const override { return p0_ + 0.5 * (eu_ + ev_); }

  private:
    glm::dvec3 pointAt(double u, double v) const override { return p0_ + u * eu_ + v * ev_; }
    bool contains(const glm::dvec3& p) const override;
    glm::dvec3 anchor() const override { return p0_; }
    glm::dvec3 p0_, eu_, ev_;
};

class DiskLight final : public PlanarLight {
  public:
    DiskLight(const glm::vec3& radiance, const glm::dvec3& centre, const glm::dvec3& normal,
              double radius);
    std::string_view kind() const override { return "disk"; }
    std::string toString() const override;
    glm::dvec3 centre() const override { return c_; }

  private:
    glm::dvec3 pointAt(double u, double v) const override;
    bool contains(const glm::dvec3& p) const override { return glm::length(p - c_) <= r_; }
    glm::dvec3 anchor() const override { return c_; }
    glm::dvec3 c_, t1_, t2_;
    double r_;
};

}  // namespace voxlight::lights
