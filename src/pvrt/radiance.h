// SPDX-License-Identifier: MIT
#pragma once
// The radiance volume of PVRT's render (Zhang, Dong & Ma 2013 §6, "early evaluation"): each frame
// the lights are projected into the basis (Basis::project → c_k), every stored point's in-scattered
// radiance S(x) = Σ_k c_k ⊙ t_k(x) is evaluated once (from the transfer, or through CPCA), and
// the ordinary ray caster marches the volume with a shader that reads S trilinearly — so a light
// change costs one pass over the stored points, not a precompute.
//
// S is clamped at 0: a truncated SH expansion of the lighting can ring below zero where the
// transfer is sharp (radiance never is). The marcher multiplies S by the segment's α and the TF
// albedo and adds the TF emission (render/shading.h), exactly as for the SH visibility shaders.
#include <glm/glm.hpp>
#include <memory>
#include <span>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"
#include "pvrt/transfer.h"
#include "render/ray_caster.h"

namespace voxlight::pvrt {

struct RadianceVolume {
    glm::ivec3 res{0};
    glm::vec3 scale{1.f};  ///< voxels per grid step (TransferLayout::scale)
    /// RGB in-scattered radiance per grid point (x fastest); 0 where no point is stored.
    std::vector<glm::vec3> values;
    /// Stored points whose combination was negative in some channel before the clamp.
    std::uint64_t clamped = 0;

    /// Trilinear S at continuous voxel coordinate p (clamped to the grid).
    glm::vec3 sample(const glm::vec3& p) const;
    std::size_t bytes() const { return values.size() * sizeof(glm::vec3); }
};

/// S = Σ_k c_k ⊙ t_k at every stored point of `transfer` (c: basis-size RGB coefficients).
/// Parallel over z-slices of the grid, deterministic.
RadianceVolume combineTransfer(const Transfer& transfer, std::span<const glm::vec3> light,
                               int threads = 0);
/// The same from per-stored-point radiance already evaluated (e.g. by CPCA): scattered into the
/// grid and clamped at 0.
RadianceVolume scatterRadiance(const TransferLayout& layout, std::span<const glm::vec3> perPoint);

/// The ray caster's shading model reading a radiance volume (in-scattered radiance, isotropic).
std::unique_ptr<render::ShadingModel> makePvrtModel(const render::RayCaster& caster,
                                                    const render::Camera& camera,
                                                    std::shared_ptr<const RadianceVolume> radiance);

}  // namespace voxlight::pvrt
