// SPDX-License-Identifier: MIT
#pragma once
// Basis lights of PVRT (Zhang, Dong & Ma 2013 §5): the distant incident radiance is written as
//   L(ω) = Σ_k c_k B_k(ω)          (ω points from the volume toward the light, lights/light.h)
// with RGB coefficients c_k and one of two bases:
//   SH of order n (n = 1…6): B_k = Y_k (sh/sh_basis.h), n² functions, c_k = ∫ L Y_k dω
//     (Light::shCoefficients of bands 0…n−1; rotation of an environment map = SH rotation)
//   DSF with 42, 162 or 642 directions (sh/dsf.h): B_k = w̄_k, c_k = s_k (Light::dsfCoefficients:
//     prefiltered / energy-conserving samples; rotation = re-sampling)
// Because the transfer is linear in the lighting, the in-scattered radiance the render needs is
//   S(x) = Σ_k c_k ⊙ t_k(x),     t_k(x) = S(x) under the incident radiance B_k
// so the precompute fills t_k per stored point (transfer.h) and every light change only projects
// the lights again (project()) and combines.
// Only distant lights (directional, environment) have a position-independent projection: point
// and area lights are an InputError naming the light.
#include <glm/glm.hpp>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "lights/light.h"
#include "sh/dsf.h"

namespace voxlight::pvrt {

enum class BasisKind { Sh, Dsf };

class Basis {
  public:
    /// SH of order n ∈ [1, kMaxShOrder]: n² functions. InputError (field `field`) otherwise.
    static Basis sh(int order, const char* field = "method.params.order");
    /// DSF with count ∈ {42, 162, 642} directions. InputError (field `field`) otherwise.
    static Basis dsf(int count, const char* field = "method.params.directions");
    static constexpr int kMaxShOrder = 6;

    BasisKind kind() const { return kind_; }
    /// Number of basis lights m.
    int size() const { return size_; }
    /// "sh16" (SH order 4) or "dsf162".
    std::string name() const;
    /// Band limit of the SH basis (order − 1); −1 for DSF.
    int shBand() const { return band_; }
    /// The DSF (null for SH).
    const sh::Dsf* dsf() const { return dsf_.get(); }

    /// The basis functions that are non-zero at a unit direction ω (toward the light): writes up
    /// to maxSupport() (index, value) pairs B_k(ω), returns their count. SH: all m (any sign);
    /// DSF: the ≤ sh::Dsf::kMaxSupport normalised weights w̄_k(ω) ≥ 0.
    int evaluate(const glm::dvec3& unitDir, int* index, float* value) const;
    int maxSupport() const;

    /// c_k of the scene's lights added together (m RGB entries). Point and area lights →
    /// InputError naming the light (PVRT precomputes for distant lighting only).
    std::vector<glm::vec3> project(
        std::span<const std::shared_ptr<const lights::Light>> lights) const;

  private:
    BasisKind kind_ = BasisKind::Sh;
    int size_ = 0;
    int band_ = -1;
    std::shared_ptr<const sh::Dsf> dsf_;
};

}  // namespace voxlight::pvrt
